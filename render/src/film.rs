//! Accumulating paths into the output layers, and writing the multi-layer EXR.

use std::path::Path;

use crate::integrator::PathSample;
use crate::spectrum::LANES;

/// Spectral bands written to the `spectral` layer, as the paper used.
pub const BANDS: usize = 16;
/// Band edges: 16 equal bands over 380..780 nm.
pub fn band_edges() -> Vec<f32> {
    (0..=BANDS).map(|i| 380.0 + 25.0 * i as f32).collect()
}

/// One pixel's running sums.
#[derive(Clone, Default)]
pub struct Pixel {
    xyz: [f64; 3],
    bands: [f64; BANDS],
    albedo: [f64; 3],
    normal: [f64; 3],
    depth: f64,
    n: u32,
}

impl Pixel {
    /// Adds one path.
    pub fn add(&mut self, s: &PathSample, y_norm: f64) {
        for i in 0..LANES {
            let (l, pdf) = (s.wavelengths.lambda[i], s.wavelengths.pdf[i]);
            if pdf <= 0.0 {
                continue;
            }
            let w = s.radiance[i] as f64 / pdf as f64 / LANES as f64;
            let c = temc::color::spectral::cmf(l as f64);
            for (acc, cmf) in self.xyz.iter_mut().zip(c) {
                *acc += cmf * w / y_norm;
            }
            let b = ((l - 380.0) / 25.0).floor();
            if (0.0..BANDS as f32).contains(&b) {
                // Mean radiance over the band: the band's integral over its width.
                self.bands[b as usize] += w / 25.0;
            }
        }
        for k in 0..3 {
            self.albedo[k] += s.albedo[k] as f64;
        }
        self.normal[0] += s.normal.0 as f64;
        self.normal[1] += s.normal.1 as f64;
        self.normal[2] += s.normal.2 as f64;
        self.depth += s.depth as f64;
        self.n += 1;
    }
}

/// A finished image: every layer as planes of f32, row-major.
#[derive(Clone)]
pub struct Layers {
    /// Width.
    pub width: usize,
    /// Height.
    pub height: usize,
    /// Linear sRGB (may hold small negative values for colours outside sRGB).
    pub color: Vec<[f32; 3]>,
    /// Mean radiance per band.
    pub spectral: Vec<[f32; BANDS]>,
    /// Albedo at the first hit.
    pub albedo: Vec<[f32; 3]>,
    /// Normal at the first hit (mean over the pixel's paths).
    pub normal: Vec<[f32; 3]>,
    /// Distance to the first hit.
    pub depth: Vec<f32>,
}

impl Layers {
    /// Averages the pixels' sums.
    pub fn from_pixels(width: usize, height: usize, px: &[Pixel]) -> Self {
        let mean = |v: f64, n: u32| (v / n.max(1) as f64) as f32;
        Layers {
            width,
            height,
            color: px
                .iter()
                .map(|p| {
                    temc::color::spectral::xyz_to_linear_srgb(p.xyz.map(|v| v / p.n.max(1) as f64))
                })
                .collect(),
            spectral: px.iter().map(|p| p.bands.map(|v| mean(v, p.n))).collect(),
            albedo: px.iter().map(|p| p.albedo.map(|v| mean(v, p.n))).collect(),
            normal: px.iter().map(|p| p.normal.map(|v| mean(v, p.n))).collect(),
            depth: px.iter().map(|p| mean(p.depth, p.n)).collect(),
        }
    }

    /// Writes one multi-layer EXR: `color.{R,G,B}`, `albedo.{R,G,B}`, `normal.{X,Y,Z}`,
    /// `depth.Z`, `spectral.b00`..`b15` (band edges 380 + 25 k nm). Written to a temporary
    /// file and renamed, so an interrupted render leaves no partial output.
    pub fn write_exr(&self, path: &Path) -> Result<(), String> {
        use exr::prelude::*;
        let n = self.width * self.height;
        let mut ch: Vec<AnyChannel<FlatSamples>> = Vec::new();
        let mut add = |name: String, f: &dyn Fn(usize) -> f32| {
            ch.push(AnyChannel::new(
                name.as_str(),
                FlatSamples::F32((0..n).map(f).collect()),
            ));
        };
        for (k, c) in ["R", "G", "B"].iter().enumerate() {
            add(format!("color.{c}"), &|i| self.color[i][k]);
            add(format!("albedo.{c}"), &|i| self.albedo[i][k]);
        }
        for (k, c) in ["X", "Y", "Z"].iter().enumerate() {
            add(format!("normal.{c}"), &|i| self.normal[i][k]);
        }
        add("depth.Z".into(), &|i| self.depth[i]);
        for b in 0..BANDS {
            add(format!("spectral.b{b:02}"), &|i| self.spectral[i][b]);
        }
        let layer = Layer::new(
            (self.width, self.height),
            LayerAttributes::default(),
            Encoding::FAST_LOSSLESS,
            AnyChannels::sort(ch.into()),
        );
        let tmp = path.with_extension(format!("tmp-{}.exr", std::process::id()));
        Image::from_layer(layer)
            .write()
            .to_file(&tmp)
            .map_err(|e| format!("{}: {e}", tmp.display()))?;
        std::fs::rename(&tmp, path).map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            format!("{}: {e}", path.display())
        })
    }
}
