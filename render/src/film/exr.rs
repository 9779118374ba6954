//! The film's output file: one multi-layer EXR with the channels of
//! [`temc_color::layers`], which `temc denoise` reads directly.

use std::path::Path;

use ::exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, WritableImage,
};
use temc_color::layers::{self, SPECTRAL_BANDS};

use super::Layers;
use crate::output::write_atomic;

impl Layers {
    /// Writes one multi-layer EXR: `color.{R,G,B}`, `albedo.{R,G,B}`, `normal.{X,Y,Z}`,
    /// `depth.Z`, `spectral.b00`..`b15` (band edges 380 + 25 k nm). Written to a temporary
    /// file and renamed, so an interrupted render leaves no partial output.
    pub fn write_exr(&self, path: &Path) -> Result<(), String> {
        let n = self.width * self.height;
        let mut ch: Vec<AnyChannel<FlatSamples>> = Vec::new();
        let mut add = |name: &str, f: &dyn Fn(usize) -> f32| {
            ch.push(AnyChannel::new(
                name,
                FlatSamples::F32((0..n).map(f).collect()),
            ));
        };
        for k in 0..3 {
            add(layers::COLOR[k], &|i| self.color[i][k]);
            add(layers::ALBEDO[k], &|i| self.albedo[i][k]);
            add(layers::NORMAL[k], &|i| self.normal[i][k]);
        }
        add(layers::DEPTH, &|i| self.depth[i]);
        for b in 0..SPECTRAL_BANDS {
            add(&layers::spectral_band(b), &|i| self.spectral[i][b]);
        }
        // The channel order does not matter: sorting by name is what the file stores.
        let layer = Layer::new(
            (self.width, self.height),
            LayerAttributes::default(),
            Encoding::FAST_LOSSLESS,
            AnyChannels::sort(ch.into()),
        );
        write_atomic(path, |tmp| Image::from_layer(layer).write().to_file(tmp))
    }
}
