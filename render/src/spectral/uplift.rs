//! Smooth RGB -> spectrum uplift after Jakob & Hanika 2019, "A Low-Dimensional Function
//! Space for Efficient Spectral Upsampling" (Computer Graphics Forum 38(2)).
//!
//! A reflectance is `r(λ) = S(c0·x² + c1·x + c2)` with `S(t) = 1/2 + t / (2·sqrt(1 + t²))`
//! and `x = (λ − 360 nm) / (830 nm − 360 nm)`, the renderer's wavelength range mapped to
//! [0, 1] (so the coefficients stay moderate and f32 keeps its precision), λ clamped to
//! the fitted 380..780 nm (see [`SigmoidPoly::eval`]). It is smooth, in [0, 1] by
//! construction, and costs three numbers.
//!
//! [`fit`] finds the coefficients whose colour under D65 matches an RGB: Levenberg–Marquardt
//! (damped Gauss–Newton) on the CIELAB difference, as the paper does. [`reflectance`]
//! interpolates a table of such fits, cheap enough for every ray hit. [`illuminant`] turns
//! an RGB into an emission spectrum, as pbrt-v4's `RGBIlluminantSpectrum` does.
//!
//! The colour of a reflectance is what the renderer's albedo buffer computes (380..=780 nm
//! per 1 nm, XYZ = Σ cmf·r·D65 / Σ ȳ·D65, then linear sRGB), divided per channel by the
//! colour of `r = 1`, which is (0.99962, 1.00024, 0.99936): the analytic CMF fit puts D65 a
//! hair off the sRGB white. Without this von Kries correction white would need `r > 1`
//! somewhere and greys would not be flat; with it the raw albedo colour of an uplifted RGB
//! differs from the RGB by that 0.06 % per channel (ΔE76 < 0.06).
//!
//! Limits, measured by the tests: the fit reaches every RGB of a 9³ grid of [0, 1]³
//! (ΔE76 < 2e-4, f32 rounding); the table's interpolation adds about 0.04 on average and
//! under 0.5 at worst. Very dark saturated colours (largest component below ~0.03) fare
//! worse, up to several ΔE76 at L* < 5: where `r ≪ 1`, `S(t) ≈ 1/(4t²)` cannot fall
//! steeply, so the function space cannot reach them and the table extrapolates there.

use std::sync::OnceLock;

use crate::spectral::measured::D65;
use crate::spectral::wavelengths::{LAMBDA_MAX, LAMBDA_MIN};

/// |t| past which `S(t)` is 0 or 1 in f32 (`1 − S(1e4) ≈ 2.5e-9`). Clamping to it keeps
/// [`SigmoidPoly::eval`] finite for the huge (or infinite) coefficients of black and white.
const T_CLAMP: f32 = 1e4;

/// `1 / (830 − 360)`: maps nm to the normalised wavelength x.
const INV_RANGE: f32 = 1.0 / (LAMBDA_MAX - LAMBDA_MIN);

/// A reflectance spectrum `S(c0·x² + c1·x + c2)`, x the normalised wavelength (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SigmoidPoly {
    /// The quadratic's coefficients, highest power first.
    pub c: [f32; 3],
}

impl SigmoidPoly {
    /// Reflectance 0 everywhere (`S(−1e4)` is exactly 0 in f32).
    const BLACK: SigmoidPoly = SigmoidPoly {
        c: [0.0, 0.0, -T_CLAMP],
    };

    /// The reflectance at `lambda_nm`: a clamp, two multiply-adds, a square root and a
    /// division. Past the fitted 380..780 nm the spectrum is held flat, as the measured
    /// tables are: colour does not constrain the quadratic there, so its extrapolation
    /// would be arbitrary (a purple's U-shape climbs to 1).
    #[inline]
    pub fn eval(&self, lambda_nm: f32) -> f32 {
        let l = lambda_nm.max(FIT_NM.0 as f32).min(FIT_NM.1 as f32);
        let x = (l - LAMBDA_MIN) * INV_RANGE;
        sigmoid((self.c[0] * x + self.c[1]) * x + self.c[2])
    }

    /// The flat spectrum `g` in [0, 1]: `S⁻¹(g) = (g − 1/2) / sqrt(g·(1 − g))`, clamped
    /// (0 and 1 give ∓∞).
    fn flat(g: f64) -> SigmoidPoly {
        let c2 = (g - 0.5) / (g * (1.0 - g)).sqrt();
        let c2 = if c2.is_nan() { -T_CLAMP as f64 } else { c2 };
        SigmoidPoly {
            c: [0.0, 0.0, c2.clamp(-T_CLAMP as f64, T_CLAMP as f64) as f32],
        }
    }
}

/// `S(t)`, t clamped so that ±∞ give 0 and 1 (and NaN 0: `max` drops it).
#[inline]
#[allow(clippy::manual_clamp)] // clamp would keep NaN
fn sigmoid(t: f32) -> f32 {
    let t = t.max(-T_CLAMP).min(T_CLAMP);
    0.5 + 0.5 * t / (1.0 + t * t).sqrt()
}

/// CIE D65 at `lambda_nm`, interpolated as the renderer's tabulated spectra are.
#[inline]
fn d65(lambda_nm: f32) -> f32 {
    let x = ((lambda_nm - 360.0) / 10.0).clamp(0.0, 47.0);
    let i = (x as usize).min(46);
    let f = x - i as f32;
    D65[i] * (1.0 - f) + D65[i + 1] * f
}

/// `Σ ȳ / Σ ȳ·D65` over 360..=830 nm per 1 nm with the tabulated CIE 1931 CMF (a test
/// checks it; with the analytic fit used before 2026-12-04 it was 0.010116228).
const D65_UNIT_SCALE: f32 = 0.010_112_242;

/// D65 scaled to the luminance of the constant spectrum 1 (`Σ ȳ·d65_unit = Σ ȳ` over
/// 360..830 nm), so that an emitter of RGB (1, 1, 1) keeps the brightness it had when
/// emitters were flat spectra.
#[inline]
pub fn d65_unit(lambda_nm: f32) -> f32 {
    d65(lambda_nm) * D65_UNIT_SCALE
}

/// An RGB emitter's spectrum: `scale · poly(λ) · d65_unit(λ)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Illuminant {
    /// The shape: a reflectance of largest component 1/2, mid-range and hence smooth.
    pub poly: SigmoidPoly,
    /// Twice the largest RGB component.
    pub scale: f32,
}

impl Illuminant {
    /// The emitted radiance at `lambda_nm`.
    #[inline]
    pub fn eval(&self, lambda_nm: f32) -> f32 {
        self.scale * self.poly.eval(lambda_nm) * d65_unit(lambda_nm)
    }
}

/// An emitter of linear sRGB `rgb`, any brightness (negative, NaN or infinite components
/// give 0 or black). Seen directly (XYZ relative to Y of the unit-flat spectrum, to linear
/// sRGB) its colour is `rgb`: D65, the sRGB white, carries the white point and the
/// reflectance `rgb / scale` the chroma.
pub fn illuminant(rgb: [f32; 3]) -> Illuminant {
    let rgb = rgb.map(|v| if v > 0.0 { v } else { 0.0 });
    let m = rgb[0].max(rgb[1]).max(rgb[2]);
    if !(m > 0.0 && m.is_finite()) {
        return Illuminant {
            poly: SigmoidPoly::BLACK,
            scale: 0.0,
        };
    }
    let scale = 2.0 * m;
    Illuminant {
        poly: reflectance(rgb.map(|v| v / scale)),
        scale,
    }
}

/// Clamps to [0, 1], NaN to 0.
fn clamp01(rgb: [f32; 3]) -> [f32; 3] {
    rgb.map(|v| if v > 0.0 { v.min(1.0) } else { 0.0 })
}

// ---------------------------------------------------------------------------------------
// The fit.

/// The fit's integration grid, nm: the albedo buffer's, per 1 nm.
const FIT_NM: (u32, u32) = (380, 780);
/// ΔE76 at which [`fit`] stops: far below what anyone sees, and about what f32
/// coefficients resolve.
const FIT_TOL: f64 = 1e-5;
/// ΔE76 at which the table's fits stop: well below its interpolation error.
const TABLE_TOL: f64 = 1e-3;
/// Weight of the Tikhonov term `REG·s·|c|` (s of [`Table`]) next to the CIELAB error.
/// For colours out of the function space's reach the closest approach has coefficients
/// running off to infinity along a flat valley; this keeps them finite and smooth from
/// colour to colour, for the table. Colours within reach stop at the tolerance first.
const REG: f64 = 1e-4;
/// Samples per [`Block`].
const LANES: usize = 4;

/// [`LANES`] samples of the fit's integration grid.
#[derive(Clone, Copy, Default)]
struct Block {
    /// Normalised wavelength.
    x: [f64; LANES],
    /// Weights of balanced XYZ (module docs): colour = Σ w·r.
    w: [[f64; LANES]; 3],
}

/// What the fit integrates against, precomputed.
struct Observer {
    /// The samples in blocks (the last padded with zero weights), laid out so that the
    /// compiler vectorises [`Observer::xyz`], the table build's hot loop.
    blocks: Vec<Block>,
    /// Linear sRGB -> XYZ.
    rgb_to_xyz: [[f64; 3]; 3],
    /// XYZ of sRGB (1, 1, 1), CIELAB's white.
    white: [f64; 3],
}

/// A CIELAB colour to fit, the regulariser's weight and the tolerance.
struct Target {
    lab: [f64; 3],
    reg: f64,
    /// ΔE76 at which the fit stops.
    tol: f64,
}

/// The outcome of [`Observer::solve`].
struct Solution {
    c: [f64; 3],
    /// CIELAB error (ΔE76).
    err: f64,
    /// Whether it reached the tolerance or stopped improving.
    converged: bool,
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn mat_vec(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    m.map(|row| dot(row, v))
}

fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

/// The inverse of `m` by cofactors; None if singular.
fn inverse(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let cof = |i: usize, j: usize| {
        let (r0, r1, c0, c1) = ((i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3);
        m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
    };
    let det = m[0][0] * cof(0, 0) + m[0][1] * cof(0, 1) + m[0][2] * cof(0, 2);
    if !(det.abs() > 1e-300 && det.is_finite()) {
        return None;
    }
    Some(std::array::from_fn(|i| {
        std::array::from_fn(|j| cof(j, i) / det)
    }))
}

impl Observer {
    fn new() -> Observer {
        use temc_color::cie::{cmf_tabulated as cmf, XYZ_TO_SRGB};
        let nm: Vec<u32> = (FIT_NM.0..=FIT_NM.1).collect();
        let e: Vec<f64> = nm.iter().map(|&l| d65(l as f32) as f64).collect();
        let ysum: f64 = nm.iter().zip(&e).map(|(&l, e)| cmf(l as f64)[1] * e).sum();
        let raw: Vec<[f64; 3]> = nm
            .iter()
            .zip(&e)
            .map(|(&l, e)| cmf(l as f64).map(|v| v * e / ysum))
            .collect();
        let flat = [0, 1, 2].map(|k| raw.iter().map(|w| w[k]).sum());
        let w_rgb = mat_vec(&XYZ_TO_SRGB, flat);
        // A fixed, well-conditioned matrix: this cannot fail.
        let rgb_to_xyz = inverse(&XYZ_TO_SRGB).expect("XYZ_TO_SRGB is invertible");
        // XYZ -> sRGB, divided by the colour of r = 1, -> XYZ.
        let balance = [0, 1, 2].map(|i| XYZ_TO_SRGB[i].map(|v| v / w_rgb[i]));
        let a = mat_mul(&rgb_to_xyz, &balance);
        let mut blocks = vec![Block::default(); nm.len().div_ceil(LANES)];
        for (n, (&l, &w)) in nm.iter().zip(&raw).enumerate() {
            let (b, i) = (&mut blocks[n / LANES], n % LANES);
            b.x[i] = (l as f64 - LAMBDA_MIN as f64) / (LAMBDA_MAX - LAMBDA_MIN) as f64;
            let w = mat_vec(&a, w);
            (0..3).for_each(|k| b.w[k][i] = w[k]);
        }
        Observer {
            blocks,
            rgb_to_xyz,
            white: mat_vec(&rgb_to_xyz, [1.0; 3]),
        }
    }

    fn get() -> &'static Observer {
        static O: OnceLock<Observer> = OnceLock::new();
        O.get_or_init(Observer::new)
    }

    /// Balanced XYZ of the spectrum with coefficients `c`, and its derivative by `c`.
    #[allow(clippy::needless_range_loop)] // lanes index several arrays in step
    fn xyz(&self, c: [f64; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
        // acc[k] = Σ w_k·S and acc[3 + 3k + m] = Σ w_k·S'·x^(2 − m), per lane.
        let mut acc = [[0.0f64; LANES]; 12];
        for b in &self.blocks {
            for i in 0..LANES {
                let x = b.x[i];
                let t = (c[0] * x + c[1]) * x + c[2];
                let inv = 1.0 / (1.0 + t * t).sqrt();
                let s = 0.5 + 0.5 * t * inv;
                let ds = 0.5 * inv * inv * inv;
                let g = [ds * x * x, ds * x, ds];
                for k in 0..3 {
                    let w = b.w[k][i];
                    acc[k][i] += w * s;
                    for m in 0..3 {
                        acc[3 + 3 * k + m][i] += w * g[m];
                    }
                }
            }
        }
        let sum = |a: [f64; LANES]| a.iter().sum::<f64>();
        (
            std::array::from_fn(|k| sum(acc[k])),
            std::array::from_fn(|k| std::array::from_fn(|m| sum(acc[3 + 3 * k + m]))),
        )
    }

    /// Balanced XYZ of the spectrum with coefficients `c`, without the derivative (about
    /// four times cheaper).
    #[allow(clippy::needless_range_loop)] // lanes index several arrays in step
    fn xyz_only(&self, c: [f64; 3]) -> [f64; 3] {
        let mut acc = [[0.0f64; LANES]; 3];
        for b in &self.blocks {
            for i in 0..LANES {
                let x = b.x[i];
                let t = (c[0] * x + c[1]) * x + c[2];
                let s = 0.5 + 0.5 * t / (1.0 + t * t).sqrt();
                for k in 0..3 {
                    acc[k][i] += b.w[k][i] * s;
                }
            }
        }
        acc.map(|a| a.iter().sum::<f64>())
    }

    /// CIELAB of `xyz` and its derivative by xyz.
    fn lab(&self, xyz: [f64; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
        const D: f64 = 6.0 / 29.0;
        let f = |k: usize| {
            let v = xyz[k] / self.white[k];
            if v > D * D * D {
                let r = v.cbrt();
                (r, 1.0 / (3.0 * r * r * self.white[k]))
            } else {
                let slope = 1.0 / (3.0 * D * D);
                (v * slope + 4.0 / 29.0, slope / self.white[k])
            }
        };
        let [(fx, dx), (fy, dy), (fz, dz)] = [f(0), f(1), f(2)];
        let lab = [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)];
        let jac = [
            [0.0, 116.0 * dy, 0.0],
            [500.0 * dx, -500.0 * dy, 0.0],
            [0.0, 200.0 * dy, -200.0 * dz],
        ];
        (lab, jac)
    }

    /// CIELAB of linear sRGB `rgb`.
    fn lab_of_rgb(&self, rgb: [f64; 3]) -> [f64; 3] {
        self.lab(mat_vec(&self.rgb_to_xyz, rgb)).0
    }

    /// The Lab residual of coefficients `c` against `lab` and its Jacobian.
    fn residual(&self, c: [f64; 3], lab: [f64; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
        let (xyz, dxyz) = self.xyz(c);
        let (l, dl) = self.lab(xyz);
        (std::array::from_fn(|k| l[k] - lab[k]), mat_mul(&dl, &dxyz))
    }

    /// The Lab residual of `c` against `lab`, without the Jacobian.
    fn residual_only(&self, c: [f64; 3], lab: [f64; 3]) -> [f64; 3] {
        let l = self.lab(self.xyz_only(c)).0;
        std::array::from_fn(|k| l[k] - lab[k])
    }

    /// What the fit minimises for `rgb`, stopping at ΔE76 `tol`.
    fn target(&self, rgb: [f64; 3], tol: f64) -> Target {
        Target {
            lab: self.lab_of_rgb(rgb),
            reg: REG * scale_of(rgb),
            tol,
        }
    }

    /// Levenberg–Marquardt from `c` towards `target`, at most `iters` steps. The Jacobian
    /// is computed at the start and after a rejected step; accepted steps update it by
    /// Broyden's rule, which halves the table build's cost (most nodes take one step).
    fn solve(&self, target: &Target, mut c: [f64; 3], iters: usize) -> Solution {
        let cost = |f: [f64; 3], c: [f64; 3]| dot(f, f) + target.reg * target.reg * dot(c, c);
        let (mut f, mut j) = self.residual(c, target.lab);
        let (mut damping, mut exact) = (1e-9, true);
        let mut converged = dot(f, f).sqrt() < target.tol;
        for _ in 0..iters {
            if converged {
                break;
            }
            let Some(step) = lm_step(&j, f, c, target.reg, damping) else {
                break;
            };
            let next = std::array::from_fn(|i| c[i] - step[i]);
            let f1 = self.residual_only(next, target.lab);
            let (before, after) = (cost(f, c), cost(f1, next));
            if after < before {
                broyden(
                    &mut j,
                    step.map(|v| -v),
                    std::array::from_fn(|k| f1[k] - f[k]),
                );
                (c, f, exact) = (next, f1, false);
                damping *= 0.1;
                // Out of reach the cost stalls at the regularised optimum instead.
                converged = dot(f, f).sqrt() < target.tol || before - after < 1e-4 * after;
            } else if exact {
                damping = (damping * 10.0).max(1e-6);
            } else {
                (f, j) = self.residual(c, target.lab);
                exact = true;
            }
        }
        Solution {
            c,
            err: dot(f, f).sqrt(),
            converged,
        }
    }
}

/// The damped Gauss–Newton step δ (to subtract from c) for the residual `f` (Jacobian
/// `j`) plus `reg·c`: `((JᵀJ + reg²·I)·(1 + μ on the diagonal)) δ = Jᵀf + reg²·c`.
fn lm_step(j: &[[f64; 3]; 3], f: [f64; 3], c: [f64; 3], reg: f64, mu: f64) -> Option<[f64; 3]> {
    let r2 = reg * reg;
    let mut a: [[f64; 3]; 3] =
        std::array::from_fn(|r| std::array::from_fn(|q| (0..3).map(|k| j[k][r] * j[k][q]).sum()));
    for (i, row) in a.iter_mut().enumerate() {
        row[i] = (row[i] + r2) * (1.0 + mu);
    }
    let g = std::array::from_fn(|r| (0..3).map(|k| j[k][r] * f[k]).sum::<f64>() + r2 * c[r]);
    Some(mat_vec(&inverse(&a)?, g))
}

/// Broyden's update of the Jacobian `j` after the step `dc` changed the residual by `df`.
fn broyden(j: &mut [[f64; 3]; 3], dc: [f64; 3], df: [f64; 3]) {
    let n = dot(dc, dc);
    if n.is_nan() || n <= 0.0 {
        return;
    }
    for (k, row) in j.iter_mut().enumerate() {
        let e = (df[k] - dot(*row, dc)) / n;
        for i in 0..3 {
            row[i] += e * dc[i];
        }
    }
}

/// Fits `to` (linear sRGB) from the coefficients `c` of `from`, splitting the straight
/// line between them in halves (at most `depth` times) where a direct solve does not
/// converge: Gauss–Newton only converges from nearby, which is why the paper walks
/// outward from grey.
fn fit_from(
    obs: &Observer,
    (from, c): ([f64; 3], [f64; 3]),
    to: [f64; 3],
    (tol, depth): (f64, u32),
) -> Solution {
    let target = obs.target(to, tol);
    let direct = obs.solve(&target, c, 30);
    if direct.converged || depth == 0 {
        return direct;
    }
    let mid = std::array::from_fn(|k| 0.5 * (from[k] + to[k]));
    let half = fit_from(obs, (from, c), mid, (tol, depth - 1));
    let walked = obs.solve(&target, half.c, 60);
    if walked.converged || walked.err < direct.err {
        walked
    } else {
        direct
    }
}

/// The coefficients whose colour under D65 is `rgb` (linear sRGB, clamped to [0, 1], NaN
/// to 0), by direct optimisation from the grey of the same mean: the slow path (tens of
/// µs to a few ms), used to build [`reflectance`]'s table and by tests. Greys are exact
/// flat spectra; colours out of reach (very dark saturated ones) get a close approach.
pub fn fit(rgb: [f32; 3]) -> SigmoidPoly {
    let rgb = clamp01(rgb).map(|v| v as f64);
    let mean = (rgb[0] + rgb[1] + rgb[2]) / 3.0;
    let grey = SigmoidPoly::flat(mean);
    if rgb[0] == rgb[1] && rgb[1] == rgb[2] {
        return grey;
    }
    let seed = ([mean; 3], grey.c.map(|v| v as f64));
    let c = fit_from(Observer::get(), seed, rgb, (FIT_TOL, 10)).c;
    SigmoidPoly {
        c: c.map(|v| v as f32),
    }
}

// ---------------------------------------------------------------------------------------
// The table.

/// Nodes per axis of [`reflectance`]'s table: 3·32³ nodes (about 83 000 fitted, the rest
/// never looked up), built in about 0.35 s on one core and committed ([`COMMITTED`]).
const RES: usize = 32;
/// The darkest slice that is fitted (largest component); darker slices are extrapolated.
const Z_DARK: f64 = 0.01;
/// Means of RGB above which [`Table::lookup`] uses the complement, blending across the
/// band.
const BLEND: (f64, f64) = (0.45, 0.55);

/// A table node: (block l, i, j, k).
type Node = (usize, usize, usize, usize);

/// Fits of RGBs in [0, 1]³ in the paper's layout: three blocks by which component `l` is
/// the largest; in each, node (i, j, k) is the RGB with component `l` = `z_k` and
/// components `l + 1`, `l + 2` (mod 3) = `x_i·z_k`, `x_j·z_k`. The ratios are `x_i = u²`
/// (u uniform), dense near 0 where saturated colours' coefficients change fastest; `z_k`
/// = smoothstep(v) (v uniform), dense near black and near full brightness, as the paper's
/// warp. Each node holds `c · s(rgb)`, `s = sqrt(μ·(1 − μ))`, μ the mean component:
/// coefficients diverge like `1/sqrt(μ)` towards black (for greys `c2·s = μ − 1/2`
/// exactly), and `c·s` stays smooth there, so it interpolates well where `c` would not.
/// Colours brighter than mid-grey are looked up by their complement, so nodes only a
/// lookup of mean ≤ `BLEND.1` reaches are fitted.
struct Table {
    res: usize,
    /// The nodes of the largest-component axis.
    z: Vec<f32>,
    /// `c · s` per node, index `((l·res + k)·res + j)·res + i`.
    d: Vec<[f32; 3]>,
}

/// Node `i` of `res` on the ratio axes.
fn node_x(i: usize, res: usize) -> f64 {
    let u = i as f64 / (res - 1) as f64;
    u * u
}

/// Node `k` of `res` on the largest-component axis.
fn node_z(k: usize, res: usize) -> f64 {
    let v = k as f64 / (res - 1) as f64;
    v * v * (3.0 - 2.0 * v)
}

/// The RGB of node `n`.
fn node_rgb((l, i, j, k): Node, res: usize) -> [f64; 3] {
    let z = node_z(k, res);
    let mut rgb = [0.0; 3];
    rgb[l] = z;
    rgb[(l + 1) % 3] = node_x(i, res) * z;
    rgb[(l + 2) % 3] = node_x(j, res) * z;
    rgb
}

/// The scale `s(rgb)` of [`Table`].
fn scale_of(rgb: [f64; 3]) -> f64 {
    let mean = (rgb[0] + rgb[1] + rgb[2]) / 3.0;
    (mean * (1.0 - mean)).max(0.0).sqrt()
}

impl Table {
    fn idx(&self, (l, i, j, k): Node) -> usize {
        ((l * self.res + k) * self.res + j) * self.res + i
    }

    /// Fits every node a lookup can reach, each seeded by extrapolating its fitted
    /// neighbours' `c·s`: from grey across the slice of largest component 1/4, then up
    /// and down in z.
    fn build(res: usize) -> Table {
        let obs = Observer::get();
        let mut t = Table {
            res,
            z: (0..res).map(|k| node_z(k, res) as f32).collect(),
            d: vec![[0.0; 3]; 3 * res * res * res],
        };
        let k0 = (0..res)
            .find(|&k| node_z(k, res) >= 0.25)
            .unwrap_or(res / 2);
        let kd = (1..res).find(|&k| node_z(k, res) >= Z_DARK).unwrap_or(1);
        for l in 0..3 {
            t.fill_slice(obs, l, k0);
            for k in k0 + 1..res {
                let from: Vec<usize> = (k.saturating_sub(3).max(k0)..k).rev().collect();
                t.fill_from_slice(obs, l, k, &from);
            }
            for k in (kd..k0).rev() {
                let from: Vec<usize> = (k + 1..=(k + 3).min(k0)).collect();
                t.fill_from_slice(obs, l, k, &from);
            }
            t.fill_dark(l, kd);
        }
        t
    }

    /// Fits node `at` from the `c·s` guess `seed`, extrapolated from nodes next to it, the
    /// nearest being `from`; where that does not converge, walks from `from`'s RGB.
    fn fit_node(&mut self, obs: &Observer, at: Node, from: Node, seed: [f64; 3]) {
        let rgb = node_rgb(at, self.res);
        let s = scale_of(rgb);
        let c = if at.1 == self.res - 1 && at.2 == self.res - 1 {
            SigmoidPoly::flat(rgb[0]).c.map(|v| v as f64)
        } else {
            let first = obs.solve(&obs.target(rgb, TABLE_TOL), seed.map(|v| v / s), 10);
            if first.converged {
                first.c
            } else {
                let from_rgb = node_rgb(from, self.res);
                let c = self.d[self.idx(from)].map(|v| v as f64 / scale_of(from_rgb));
                fit_from(obs, (from_rgb, c), rgb, (TABLE_TOL, 4)).c
            }
        };
        let n = self.idx(at);
        self.d[n] = c.map(|v| (v * s) as f32);
    }

    /// Whether a lookup of mean at most `BLEND.1` can reach node `n`: a cell only holds
    /// colours brighter than its lowest corner.
    fn needed(&self, (l, i, j, k): Node) -> bool {
        let low = (
            l,
            i.saturating_sub(1),
            j.saturating_sub(1),
            k.saturating_sub(1),
        );
        let rgb = node_rgb(low, self.res);
        (rgb[0] + rgb[1] + rgb[2]) / 3.0 <= BLEND.1
    }

    /// The slices below `kd`, down to black, extrapolated linearly from slices `kd` and
    /// `kd + 1`: fits there are costly and poor (saturated colours that dark are out of
    /// reach), while `c·s` changes slowly as z → 0 (`r ≈ 1/(4t²)` scales with `s²`).
    fn fill_dark(&mut self, l: usize, kd: usize) {
        for k in 0..kd {
            for j in 0..self.res {
                for i in 0..self.res {
                    let a = self.d[self.idx((l, i, j, kd))];
                    let b = self.d[self.idx((l, i, j, kd + 1))];
                    let f = (kd - k) as f32;
                    let n = self.idx((l, i, j, k));
                    self.d[n] = std::array::from_fn(|m| a[m] + (a[m] - b[m]) * f);
                }
            }
        }
    }

    /// The `c·s` guess for a node from up to three fitted nodes before it on a line,
    /// nearest first: polynomial extrapolation of the degree they allow.
    fn predict(&self, prev: &[Node]) -> [f64; 3] {
        let d = |n: usize| self.d[self.idx(prev[n])].map(|v| v as f64);
        match prev.len() {
            0 => [0.0; 3],
            1 => d(0),
            2 => std::array::from_fn(|m| 2.0 * d(0)[m] - d(1)[m]),
            _ => std::array::from_fn(|m| 3.0 * d(0)[m] - 3.0 * d(1)[m] + d(2)[m]),
        }
    }

    /// Walks slice k from its grey corner (i = j = res − 1) along each row, each row's
    /// first node seeded from the rows above.
    fn fill_slice(&mut self, obs: &Observer, l: usize, k: usize) {
        let r = self.res;
        for j in (0..r).rev() {
            for i in (0..r).rev() {
                let prev: Vec<Node> = if i + 1 < r {
                    (i + 1..r.min(i + 4)).map(|i| (l, i, j, k)).collect()
                } else {
                    (j + 1..r.min(j + 4)).map(|j| (l, i, j, k)).collect()
                };
                let from = prev.first().copied().unwrap_or((l, i, j, k));
                let seed = self.predict(&prev);
                self.fit_node(obs, (l, i, j, k), from, seed);
            }
        }
    }

    /// Fits the reachable nodes of slice k from the fitted slices `from`, nearest first.
    fn fill_from_slice(&mut self, obs: &Observer, l: usize, k: usize, from: &[usize]) {
        for j in 0..self.res {
            for i in 0..self.res {
                if !self.needed((l, i, j, k)) {
                    continue;
                }
                let prev: Vec<Node> = from.iter().map(|&f| (l, i, j, f)).collect();
                let seed = self.predict(&prev);
                self.fit_node(obs, (l, i, j, k), prev[0], seed);
            }
        }
    }

    /// Cell index and fraction of `u` in [0, 1] on a uniform axis.
    fn cell(&self, u: f32) -> (usize, f32) {
        let x = u * (self.res - 1) as f32;
        let i = (x as usize).min(self.res - 2);
        (i, (x - i as f32).clamp(0.0, 1.0))
    }

    /// The coefficients at `rgb` (in [0, 1]). Colours brighter than mid-grey use the
    /// complement, by the symmetry `S(−t) = 1 − S(t)`: the spectrum `1 − r` has the colour
    /// `(1, 1, 1) − rgb`, so `fit(rgb) = −fit(1 − rgb)`. Near white thus becomes near
    /// black, where the table's axes separate brightness from chroma; across a band of
    /// means both are blended so that the switch is continuous.
    fn lookup(&self, rgb: [f32; 3]) -> SigmoidPoly {
        if rgb[0] == rgb[1] && rgb[1] == rgb[2] {
            return SigmoidPoly::flat(rgb[0] as f64);
        }
        let mean = (rgb[0] as f64 + rgb[1] as f64 + rgb[2] as f64) / 3.0;
        let direct = || self.lookup_dark(rgb, mean);
        let flipped = || {
            let c = self.lookup_dark(rgb.map(|v| 1.0 - v), 1.0 - mean);
            c.map(|v| -v)
        };
        if mean <= BLEND.0 {
            return SigmoidPoly { c: direct() };
        }
        if mean >= BLEND.1 {
            return SigmoidPoly { c: flipped() };
        }
        let u = ((mean - BLEND.0) / (BLEND.1 - BLEND.0)) as f32;
        let w = u * u * (3.0 - 2.0 * u);
        let (a, b) = (direct(), flipped());
        SigmoidPoly {
            c: std::array::from_fn(|m| a[m] + (b[m] - a[m]) * w),
        }
    }

    /// Trilinear interpolation of `c·s` at `rgb` of mean `mean` (at most `BLEND.1`),
    /// divided by `s`.
    fn lookup_dark(&self, rgb: [f32; 3], mean: f64) -> [f32; 3] {
        if mean < 1e-9 {
            return SigmoidPoly::BLACK.c;
        }
        let l = if rgb[0] >= rgb[1] && rgb[0] >= rgb[2] {
            0
        } else if rgb[1] >= rgb[2] {
            1
        } else {
            2
        };
        let z = rgb[l];
        let (i, fx) = self.cell((rgb[(l + 1) % 3] / z).sqrt());
        let (j, fy) = self.cell((rgb[(l + 2) % 3] / z).sqrt());
        let k = (self.z.partition_point(|&n| n <= z).max(1) - 1).min(self.res - 2);
        let fz = ((z - self.z[k]) / (self.z[k + 1] - self.z[k])).clamp(0.0, 1.0);
        let mut d = [0.0f32; 3];
        for (dk, wk) in [(0, 1.0 - fz), (1, fz)] {
            for (dj, wj) in [(0, 1.0 - fy), (1, fy)] {
                for (di, wi) in [(0, 1.0 - fx), (1, fx)] {
                    let n = self.d[self.idx((l, i + di, j + dj, k + dk))];
                    let w = wi * wj * wk;
                    (0..3).for_each(|m| d[m] += w * n[m]);
                }
            }
        }
        let s = (mean * (1.0 - mean)).sqrt() as f32;
        d.map(|v| v / s)
    }
}

/// [`Table::build`]`(RES)`'s nodes, committed: building them took 0.35 s of every render
/// process (17 % of a 256x256, 16 spp render), for a result that never changes.
/// Little-endian f32 `c·s` triples in [`Table::idx`] order; the test
/// `committed_table_is_the_built_one` checks it against a fresh build, and
/// `TEMC_BLESS=1 cargo test --release -p temc-render committed_table` rewrites it.
static COMMITTED: &[u8] = include_bytes!("uplift_table.bin");

impl Table {
    /// A table of `res` from `bytes` in [`COMMITTED`]'s layout; None if the size is not
    /// that of `res`.
    fn from_bytes(bytes: &[u8], res: usize) -> Option<Table> {
        if bytes.len() != 3 * res * res * res * 12 {
            return None;
        }
        let f = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        Some(Table {
            res,
            z: (0..res).map(|k| node_z(k, res) as f32).collect(),
            d: bytes
                .chunks_exact(12)
                .map(|c| [f(&c[0..4]), f(&c[4..8]), f(&c[8..12])])
                .collect(),
        })
    }

    /// The nodes in [`COMMITTED`]'s layout.
    #[cfg(test)]
    fn to_bytes(&self) -> Vec<u8> {
        self.d
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect()
    }
}

/// The committed table; built afresh only if the committed file does not hold one of RES
/// (the test above fails then).
fn table() -> &'static Table {
    static T: OnceLock<Table> = OnceLock::new();
    T.get_or_init(|| Table::from_bytes(COMMITTED, RES).unwrap_or_else(|| Table::build(RES)))
}

/// The reflectance of linear sRGB `rgb` (clamped to [0, 1], NaN to 0) from a table of
/// [`fit`]s, interpolated: a texture lookup's cost, for every ray hit.
pub fn reflectance(rgb: [f32; 3]) -> SigmoidPoly {
    table().lookup(clamp01(rgb))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Per nm of 380..=780: the CMF times D65, normalised by Σ ȳ·D65.
    fn albedo_weights() -> &'static Vec<[f64; 3]> {
        static W: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
        W.get_or_init(|| {
            let w: Vec<[f64; 3]> = (380..=780)
                .map(|l| temc_color::cie::cmf_tabulated(l as f64).map(|c| c * d65(l as f32) as f64))
                .collect();
            let ysum: f64 = w.iter().map(|c| c[1]).sum();
            w.iter().map(|c| c.map(|v| v / ysum)).collect()
        })
    }

    /// Linear sRGB of reflectance `r` under D65 as the albedo buffer integrates it.
    fn albedo(r: impl Fn(f32) -> f32) -> [f64; 3] {
        let mut xyz = [0.0; 3];
        for (n, w) in albedo_weights().iter().enumerate() {
            let v = r(380.0 + n as f32) as f64;
            (0..3).for_each(|k| xyz[k] += w[k] * v);
        }
        mat_vec(&temc_color::cie::XYZ_TO_SRGB, xyz)
    }

    /// [`albedo`] divided by the albedo of `r = 1` (module docs).
    fn colour(r: impl Fn(f32) -> f32) -> [f64; 3] {
        let (a, w) = (albedo(r), albedo(|_| 1.0));
        std::array::from_fn(|k| a[k] / w[k])
    }

    fn delta_e(a: [f64; 3], b: [f64; 3]) -> f64 {
        let obs = Observer::get();
        let (la, lb) = (obs.lab_of_rgb(a), obs.lab_of_rgb(b));
        (0..3).map(|k| (la[k] - lb[k]).powi(2)).sum::<f64>().sqrt()
    }

    /// ΔE76 between `rgb` and the colour of `p`.
    fn error(p: SigmoidPoly, rgb: [f32; 3]) -> f64 {
        delta_e(colour(|l| p.eval(l)), rgb.map(|v| v as f64))
    }

    fn grid(n: usize) -> Vec<[f32; 3]> {
        let v = |i: usize| i as f32 / (n - 1) as f32;
        (0..n * n * n)
            .map(|i| [v(i / (n * n)), v(i / n % n), v(i % n)])
            .collect()
    }

    /// Uniform [0, 1) from a fixed-seed xorshift.
    fn rng(mut state: u64) -> impl FnMut() -> f32 {
        move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// Max and mean of ΔE76 of `uplift` over `colours`.
    fn stats(colours: &[[f32; 3]], uplift: impl Fn([f32; 3]) -> SigmoidPoly) -> (f64, f64) {
        let e: Vec<f64> = colours.iter().map(|&c| error(uplift(c), c)).collect();
        let max = e.iter().fold(0.0f64, |a, &b| a.max(b));
        (max, e.iter().sum::<f64>() / e.len() as f64)
    }

    #[test]
    fn fit_round_trips_a_grid_including_the_corners() {
        // Measured: max 1.1e-4, mean 1.3e-5; what remains is f32 rounding of the
        // coefficients.
        let colours = grid(9);
        let (max, mean) = stats(&colours, fit);
        assert!(max < 5e-4 && mean < 5e-5, "max {max} mean {mean}");
        // The raw albedo colour (without the 0.06 % white correction) is off by that.
        let raw = colours.iter().map(|&c| {
            let p = fit(c);
            delta_e(albedo(|l| p.eval(l)), c.map(|v| v as f64))
        });
        let worst = raw.fold(0.0f64, f64::max);
        // Measured: 0.057.
        assert!(worst < 0.08, "{worst}");
    }

    #[test]
    fn table_round_trips_random_colours() {
        // Measured over these 4000: max 0.16, mean 0.037 (over 20 000 others: max 0.42, at
        // a dark saturated red). Trilinear interpolation at res 32 is what limits it.
        let mut next = rng(12345);
        let colours: Vec<[f32; 3]> = (0..4000).map(|_| [next(), next(), next()]).collect();
        let (max, mean) = stats(&colours, reflectance);
        assert!(max < 0.25 && mean < 0.045, "max {max} mean {mean}");
    }

    #[test]
    fn table_is_poorer_but_bounded_on_very_dark_colours() {
        // Largest component below 0.03 (sRGB code value below 48 of 255): the function
        // space cannot reach dark saturated colours, and the table extrapolates below
        // 0.012. Measured: max 4.1, mean 0.14; the direct fit: max 0.26, mean 0.005.
        let mut next = rng(777);
        let colours: Vec<[f32; 3]> = (0..300)
            .map(|_| {
                let z = 0.03 * next();
                [next() * z, next() * z, z]
            })
            .collect();
        let (max, mean) = stats(&colours, reflectance);
        assert!(max < 6.0 && mean < 0.2, "max {max} mean {mean}");
    }

    #[test]
    fn reflectances_stay_in_0_1() {
        let mut next = rng(99);
        for n in 0..3000 {
            // Some components outside [0, 1], to exercise the clamps.
            let rgb = [0; 3].map(|_| next() * 1.4 - 0.2);
            let p = if n % 10 == 0 {
                fit(rgb)
            } else {
                reflectance(rgb)
            };
            for l in 360..=830 {
                let v = p.eval(l as f32);
                assert!((0.0..=1.0).contains(&v), "{rgb:?} {l} nm: {v} ({p:?})");
            }
        }
    }

    #[test]
    fn white_grey_and_black_are_flat() {
        let flat = |p: SigmoidPoly, g: f32, tol: f32| {
            for l in 360..=830 {
                let v = p.eval(l as f32);
                assert!((v - g).abs() <= tol, "{p:?} at {l} nm: {v}, not {g}");
            }
        };
        for uplift in [fit, reflectance] {
            flat(uplift([1.0; 3]), 1.0, 1e-4);
            flat(uplift([0.0; 3]), 0.0, 1e-6);
            flat(uplift([f32::NAN, -1.0, 0.0]), 0.0, 1e-6);
            flat(uplift([2.0, 1.5, 1.0]), 1.0, 1e-4);
            for g in [1e-4, 0.01, 0.1, 0.18, 0.5, 0.77, 0.9, 0.999] {
                flat(uplift([g; 3]), g, 1e-3 * g.max(0.01));
            }
        }
        // Near-greys and near-white go through the table's interpolation.
        flat(reflectance([0.5, 0.5, 0.5001]), 0.5, 1e-3);
        flat(reflectance([1.0, 1.0, 0.9999]), 1.0, 1e-3);
        flat(reflectance([1e-4, 1e-4, 1.1e-4]), 1e-4, 1e-3);
    }

    /// Largest difference of the two spectra over 360..830 nm.
    fn spectral_distance(a: SigmoidPoly, b: SigmoidPoly) -> f32 {
        (360..=830)
            .map(|l| (a.eval(l as f32) - b.eval(l as f32)).abs())
            .fold(0.0, f32::max)
    }

    #[test]
    fn the_table_is_continuous_across_its_seams() {
        // Steps of 1e-3 in RGB, random and across the seams: where the largest component
        // switches (r = g etc.), across the blend band (means 0.45..0.55) and its ends,
        // along the ratio diagonal. Some colours' spectra are that sensitive themselves
        // (near white and black, and saturated: up to 0.15, mostly at the weakly seen
        // ends of the range), so a step larger than 0.01 must follow the direct fit's.
        let mut next = rng(4242);
        let mut bases: Vec<[f32; 3]> = (0..1000).map(|_| [next(), next(), next()]).collect();
        for _ in 0..200 {
            let (a, b) = (next(), next());
            bases.extend([[a, a, b], [b, a, a], [0.9, a * 0.9, a * 0.9]]);
            let m = 3.0 * (0.45 + 0.1 * next());
            bases.extend([[m * a, m * (1.0 - a), 0.0].map(|v| v.min(1.0))]);
            bases.extend([[0.85 - a, a, 0.5], [1.15 - a, a, 0.5]].map(clamp01));
        }
        let mut worst = 0.0f32;
        for base in bases {
            for axis in 0..3 {
                let mut q = base;
                q[axis] += 1e-3;
                let step = spectral_distance(reflectance(base), reflectance(q));
                if step > 0.01 {
                    let direct = spectral_distance(fit(base), fit(q));
                    worst = worst.max(step - direct);
                    assert!(
                        step < 1.5 * direct + 0.01,
                        "{base:?} {axis}: {step} vs {direct}"
                    );
                }
            }
        }
        // Measured: the table's step exceeds the fit's by at most 0.003.
        assert!(worst < 0.01, "{worst}");
    }

    #[test]
    fn table_matches_fit_at_its_nodes() {
        // Nodes of largest component from 0.026 (k = 3) up: darker, saturated colours are
        // out of reach and fit and table may settle on different closest spectra.
        // Measured: at most 6.6e-4 apart (the table's fits stop at ΔE 1e-3). Under the
        // CIE table (2026-12-04) the direct fit stalls at ΔE 8.4 at one node, saturated
        // blue (0, 0.009, 0.33), which the table reaches to ΔE 5e-5.
        let t = table();
        let (mut worst, mut stalled) = (0.0f32, 0);
        for l in 0..3 {
            for k in (3..RES).step_by(3) {
                for j in (0..RES).step_by(5) {
                    for i in (0..RES).step_by(4) {
                        let rgb = node_rgb((l, i, j, k), RES).map(|v| v as f32);
                        let mean = (rgb[0] + rgb[1] + rgb[2]) as f64 / 3.0;
                        if mean > BLEND.0 {
                            continue;
                        }
                        let direct = fit(rgb);
                        if error(direct, rgb) > 0.01 {
                            // The direct walk from grey stalled where the table's walk
                            // from its neighbours did not: the table must reach it.
                            stalled += 1;
                            assert!(error(t.lookup(rgb), rgb) < 0.01, "{rgb:?}");
                            continue;
                        }
                        worst = worst.max(spectral_distance(t.lookup(rgb), direct));
                    }
                }
            }
        }
        assert!(worst < 1.5e-3, "{worst}");
        assert!(stalled <= 1, "the direct fit stalled at {stalled} nodes");
    }

    /// Linear sRGB of an emitter seen directly: XYZ relative to Y of the unit-flat
    /// spectrum, over 360..=830 nm.
    fn emitted(e: Illuminant) -> [f64; 3] {
        use temc_color::cie::cmf_tabulated as cmf;
        let (mut xyz, mut y1) = ([0.0; 3], 0.0);
        for l in 360..=830 {
            let (c, v) = (cmf(l as f64), e.eval(l as f32) as f64);
            (0..3).for_each(|k| xyz[k] += c[k] * v);
            y1 += c[1];
        }
        mat_vec(&temc_color::cie::XYZ_TO_SRGB, xyz.map(|v| v / y1))
    }

    #[test]
    fn illuminants_have_their_colour() {
        use temc_color::cie::cmf_tabulated as cmf;
        let (y1, yd): (f64, f64) = (360..=830)
            .map(|l| {
                (
                    cmf(l as f64)[1],
                    cmf(l as f64)[1] * d65_unit(l as f32) as f64,
                )
            })
            .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
        assert!((yd / y1 - 1.0).abs() < 1e-6, "{yd} vs {y1}");
        let white = emitted(illuminant([1.0; 3]));
        assert!(white.iter().all(|v| (v - 1.0).abs() < 1e-3), "{white:?}");
        // Measured: errors up to 0.11 % of the brightest component, the table's
        // interpolation and the white correction together; white is (0.99949, 1.00025,
        // 0.99958).
        for rgb in [
            [1.0, 0.0, 0.0],
            [0.0, 3.0, 0.0],
            [0.0, 0.0, 0.5],
            [2.0, 1.5, 0.1],
        ] {
            let got = emitted(illuminant(rgb));
            let m = rgb.iter().fold(0.0f32, |a, &b| a.max(b)) as f64;
            let off = (0..3)
                .map(|k| (got[k] - rgb[k] as f64).abs())
                .fold(0.0, f64::max);
            assert!(off < 5e-3 * m, "{rgb:?} -> {got:?}");
        }
        let dark = illuminant([-1.0, 0.0, f32::NAN]);
        assert_eq!((dark.scale, dark.eval(550.0)), (0.0, 0.0));
        assert_eq!(illuminant([f32::INFINITY, 0.0, 0.0]).scale, 0.0);
    }

    /// The committed table is a fresh build's, to within what another platform's `f64`
    /// maths may move it (bit-identical where it was written).
    #[test]
    fn committed_table_is_the_built_one() {
        let built = Table::build(RES);
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/src/spectral/uplift_table.bin");
        if std::env::var_os("TEMC_BLESS").is_some() {
            std::fs::write(path, built.to_bytes()).unwrap();
            return;
        }
        let held = Table::from_bytes(COMMITTED, RES).expect(
            "uplift_table.bin does not hold a table of RES nodes: run \
             TEMC_BLESS=1 cargo test --release -p temc-render committed_table",
        );
        let worst = built
            .d
            .iter()
            .zip(&held.d)
            .flat_map(|(a, b)| (0..3).map(move |m| (a[m] - b[m]).abs() / (1.0 + a[m].abs())))
            .fold(0.0f32, f32::max);
        assert!(
            worst < 1e-5,
            "uplift_table.bin differs from a fresh build by {worst}"
        );
        assert!(std::ptr::eq(table(), table()));
        assert_eq!(table().d.len(), built.d.len());
    }
}
