//! The scene file format: one statement per line, `#` starts a comment, keys may come in
//! any order. Errors name the file and line (and the CSV file's line for tables read from
//! one).
//!
//! ```text
//! camera eye X Y Z target X Y Z fov DEGREES
//! environment SPECTRUM [scale S]
//! material NAME diffuse reflectance REFL
//! material NAME conductor (metal Au|Ag|Cu|Al | eta SPECTRUM k SPECTRUM) [roughness STEX] [distribution DIST]
//! material NAME dielectric (ior N | ior SPECTRUM | cauchy A B | sellmeier bk7|sf11 | sellmeier B1 B2 B3 C1 C2 C3) [roughness STEX] [distribution DIST]
//! material NAME plastic reflectance REFL [ior N] [roughness STEX]
//! material NAME emitter SPECTRUM [scale S] [two-sided]
//! sphere center X Y Z radius R material NAME
//! quad corner X Y Z edge1 X Y Z edge2 X Y Z material NAME
//! box min X Y Z max X Y Z [rotate DEGREES] material NAME
//! prism center X Y Z size S height H [rotate DEGREES] material NAME
//! torus center X Y Z radii MAJOR MINOR [tilt DEGREES] material NAME
//! mesh file PATH.obj [scale S] [rotate DEGREES] [translate X Y Z] material NAME
//!
//! REFL     = TEX | spectrum SPECTRUM            (a measured reflectance, values in [0, 1])
//! TEX      = rgb R G B | PATTERN R G B R G B FREQ
//! STEX     = VALUE | PATTERN A B FREQ          (the microfacet alpha; 0 is smooth)
//! DIST     = ggx | beckmann                    (microfacet distribution; default ggx)
//! PATTERN  = checker | stripes | noise | fine
//! SPECTRUM = constant V | blackbody KELVIN | d65 | fluorescent | laser NM [WIDTH_NM] | rgb R G B
//!          | table NM V [NM V ...] | csv PATH.csv
//! ```
//!
//! `table` and `csv` give a measured spectrum as (wavelength in nm, value) pairs with
//! increasing wavelengths, linearly interpolated and held flat outside; a CSV file has one
//! pair a line (comma, semicolon or blank separated, `#` comments and one header line
//! allowed), resolved next to the scene file. A line spectrum is written directly, e.g.
//! `table 540 0.02 545 3 550 0.02 ...`; narrow peaks make the renderer sample wavelengths
//! from the emitters' spectra.
//!
//! `rgb R G B` (linear sRGB in [0, 1]) is uplifted smoothly ([`crate::spectral::uplift`]):
//! as a reflectance, to a spectrum whose colour under D65 is the RGB; as an emitter, to such
//! a spectrum times D65, whose colour seen directly is the RGB. It is refused for a
//! conductor's or dielectric's optical constants.
//!
//! Emitters are one-sided: a quad or triangle emits along `edge1 x edge2`, a sphere outwards;
//! `two-sided` emits from both faces. Emitter and environment `scale` is a luminance: the
//! spectrum is divided by its own luminance first, so a D65 lamp and a laser with the same
//! scale are equally bright. `rotate` turns about the vertical (y) axis; `tilt` about x.
//! Mesh and CSV paths are relative to the scene file. The world is right-handed with y up
//! (see [`crate::camera::Camera`]).

use std::collections::HashMap;
use std::path::Path;

use crate::camera::Camera;
use crate::description::obj;
use crate::geometry::shape::{boxed, prism, rotate_y, torus, Prim};
use crate::geometry::vec3::V3;
use crate::materials::ior::{Ior, BK7, SF11};
use crate::materials::scattering::Distribution;
use crate::materials::texture::{Pattern, Texture};
use crate::materials::{metal, metal_albedo, Material, Metal, Reflectance};
use crate::scene::Scene;
use crate::spectral::spectrum::Spectrum;

struct Cursor<'a> {
    toks: Vec<&'a str>,
    pos: usize,
    /// Where CSV files are resolved (None: refused).
    dir: Option<&'a Path>,
}

type Res<T> = Result<T, String>;

impl<'a> Cursor<'a> {
    fn done(&self) -> bool {
        self.pos >= self.toks.len()
    }
    fn peek(&self) -> Option<&'a str> {
        self.toks.get(self.pos).copied()
    }
    fn word(&mut self, what: &str) -> Res<&'a str> {
        let t = self
            .peek()
            .ok_or_else(|| format!("expected {what} at the end of the line"))?;
        self.pos += 1;
        Ok(t)
    }
    fn num(&mut self, what: &str) -> Res<f32> {
        let t = self.word(what)?;
        match t.parse::<f32>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(format!("expected a number for {what}, found '{t}'")),
        }
    }
    fn pos_num(&mut self, what: &str) -> Res<f32> {
        let v = self.num(what)?;
        if v > 0.0 {
            Ok(v)
        } else {
            Err(format!("{what} must be positive, found {v}"))
        }
    }
    fn next_is_num(&self) -> bool {
        self.peek().is_some_and(|t| t.parse::<f32>().is_ok())
    }
    fn v3(&mut self, what: &str) -> Res<V3> {
        Ok(V3(self.num(what)?, self.num(what)?, self.num(what)?))
    }
    fn rgb(&mut self, what: &str) -> Res<[f32; 3]> {
        let c = [self.num(what)?, self.num(what)?, self.num(what)?];
        if c.iter().any(|v| !(0.0..=1.0).contains(v)) {
            return Err(format!("{what} must lie in [0, 1], found {c:?}"));
        }
        Ok(c)
    }
    fn pattern(&mut self) -> Option<Pattern> {
        let p = match self.peek()? {
            "checker" => Pattern::Checker,
            "stripes" => Pattern::Stripes,
            "noise" => Pattern::Noise,
            "fine" => Pattern::Fine,
            _ => return None,
        };
        self.pos += 1;
        Some(p)
    }
    fn texture(&mut self) -> Res<Texture> {
        if let Some(pattern) = self.pattern() {
            let a = self.rgb("a texture colour")?;
            let b = self.rgb("a texture colour")?;
            let freq = self.pos_num("a texture frequency")?;
            return Ok(Texture {
                pattern,
                a,
                b,
                freq,
            });
        }
        match self.word("a texture (rgb, checker, stripes, noise, fine)")? {
            "rgb" => Ok(Texture::uniform(self.rgb("an rgb colour")?)),
            t => Err(format!(
                "unknown texture '{t}' (rgb, checker, stripes, noise, fine)"
            )),
        }
    }
    fn scalar_texture(&mut self, lo: f32, hi: f32) -> Res<Texture> {
        let check = |v: f32| {
            if (lo..=hi).contains(&v) {
                Ok(v)
            } else {
                Err(format!("value must lie in [{lo}, {hi}], found {v}"))
            }
        };
        if let Some(pattern) = self.pattern() {
            let a = check(self.num("a texture value")?)?;
            let b = check(self.num("a texture value")?)?;
            let freq = self.pos_num("a texture frequency")?;
            return Ok(Texture {
                pattern,
                a: [a; 3],
                b: [b; 3],
                freq,
            });
        }
        Ok(Texture::scalar(check(self.num("a value")?)?))
    }
    /// A spectrum; tables and constants must have values in `range`.
    fn spectrum(&mut self, range: (f32, f32)) -> Res<Spectrum> {
        match self.word("a spectrum")? {
            "constant" => {
                let v = self.num("the constant")?;
                if !(range.0..=range.1).contains(&v) {
                    return Err(format!("constant {v} is outside {}..{}", range.0, range.1));
                }
                Ok(Spectrum::Constant(v))
            }
            "blackbody" => {
                let k = self.pos_num("the temperature")?;
                if !(500.0..=50000.0).contains(&k) {
                    return Err(format!("blackbody temperature {k} K is outside 500..50000"));
                }
                Ok(Spectrum::Blackbody(k))
            }
            "d65" => Ok(Spectrum::d65()),
            "fluorescent" => Ok(Spectrum::fluorescent()),
            "laser" => {
                let nm = self.num("the laser wavelength")?;
                if !(380.0..=780.0).contains(&nm) {
                    return Err(format!("laser wavelength {nm} nm is outside 380..780"));
                }
                let w = if self.next_is_num() {
                    self.pos_num("the line width")?
                } else {
                    1.0
                };
                Ok(Spectrum::laser(nm, w))
            }
            "rgb" => {
                let rgb = self.rgb("an rgb spectrum")?;
                if range.1 <= 1.0 {
                    Ok(Spectrum::rgb_reflectance(rgb))
                } else if range == EMISSION {
                    Ok(Spectrum::rgb_illuminant(rgb))
                } else {
                    Err("rgb is for reflectances and emitters; give optical constants as a \
                         constant, a table or a CSV file"
                        .into())
                }
            }
            "table" => {
                let mut points = Vec::new();
                while self.next_is_num() {
                    points.push((self.num("a wavelength")?, self.num("a table value")?));
                }
                Spectrum::sampled(points, range)
            }
            "csv" => {
                let file = self.word("a CSV file name")?;
                let dir = self.dir.ok_or("CSV files need the scene to come from a file")?;
                let path = dir.join(file);
                let text = std::fs::read_to_string(&path)
                    .map_err(|e| format!("{}: {e}", path.display()))?;
                let points = csv_pairs(&text).map_err(|e| format!("{}:{e}", path.display()))?;
                Spectrum::sampled(points, range).map_err(|e| format!("{}: {e}", path.display()))
            }
            t => Err(format!(
                "unknown spectrum '{t}' (constant, blackbody, d65, fluorescent, laser, rgb, table, csv)"
            )),
        }
    }

    /// A diffuse or plastic reflectance: an RGB texture, or `spectrum SPECTRUM`.
    fn reflectance(&mut self) -> Res<Reflectance> {
        if self.peek() == Some("spectrum") {
            self.pos += 1;
            return Ok(Reflectance::spectral(self.spectrum((0.0, 1.0))?));
        }
        Ok(Reflectance::texture(self.texture()?))
    }
}

/// (wavelength, value) pairs of a CSV file: one pair a line, separated by a comma,
/// semicolon or blanks; `#` comments, blank lines and one header line are skipped. Errors
/// start with the line number.
fn csv_pairs(text: &str) -> Res<Vec<(f32, f32)>> {
    let mut points = Vec::new();
    let mut header_seen = false;
    for (ln, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let f: Vec<&str> = line
            .split(|c: char| c == ',' || c == ';' || c.is_whitespace())
            .filter(|t| !t.is_empty())
            .collect();
        let nums: Vec<Option<f32>> = f.iter().map(|t| t.parse::<f32>().ok()).collect();
        match nums.as_slice() {
            [Some(l), Some(v)] if l.is_finite() && v.is_finite() => points.push((*l, *v)),
            _ if points.is_empty() && !header_seen && nums.iter().any(Option::is_none) => {
                header_seen = true
            }
            _ => {
                return Err(format!(
                    "{}: expected 'wavelength, value', found '{line}'",
                    ln + 1
                ))
            }
        }
    }
    Ok(points)
}

/// The values an emission spectrum may take.
const EMISSION: (f32, f32) = (0.0, f32::MAX);

/// Scales a spectrum by `scale` over its luminance; refuses black spectra.
fn emitter(spectrum: Spectrum, scale: f32) -> Res<(Spectrum, f32)> {
    let lum = spectrum.luminance();
    if lum <= 0.0 {
        return Err("the spectrum has no visible power".into());
    }
    Ok((spectrum, scale / lum))
}

/// The keys of a shape statement: numbers by key, the material, a mesh's file.
struct ShapeKeys<'a> {
    values: HashMap<&'a str, Vec<f32>>,
    material: Option<usize>,
    file: Option<&'a str>,
}

impl ShapeKeys<'_> {
    fn get(&self, head: &str, k: &str) -> Res<Vec<f32>> {
        self.values
            .get(k)
            .cloned()
            .ok_or_else(|| format!("{head} needs '{k}'"))
    }
}

fn v3(v: Vec<f32>) -> V3 {
    V3(v[0], v[1], v[2])
}

fn positive(v: f32, what: &str) -> Res<f32> {
    if v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{what} must be positive"))
    }
}

/// A camera statement's keys.
fn camera(c: &mut Cursor) -> Res<Camera> {
    let (mut eye, mut target, mut fov) = (None, None, None);
    while !c.done() {
        match c.word("a key")? {
            "eye" => eye = Some(c.v3("eye")?),
            "target" => target = Some(c.v3("target")?),
            "fov" => {
                let f = c.pos_num("fov")?;
                if f >= 179.0 {
                    return Err(format!("fov {f} must be below 179 degrees"));
                }
                fov = Some(f)
            }
            k => return Err(format!("unknown camera key '{k}' (eye, target, fov)")),
        }
    }
    let eye = eye.ok_or("camera needs 'eye'")?;
    let target = target.ok_or("camera needs 'target'")?;
    if (target - eye).len() <= 0.0 {
        return Err("camera eye and target coincide".into());
    }
    let dir = (target - eye).norm();
    if dir.1.abs() > 0.999 {
        return Err("camera must not look straight up or down".into());
    }
    Ok(Camera {
        eye,
        target,
        fov_deg: fov.unwrap_or(40.0),
    })
}

/// An environment statement: a spectrum and its scale.
fn environment(c: &mut Cursor) -> Res<(Spectrum, f32)> {
    let s = c.spectrum(EMISSION)?;
    let mut scale = 1.0;
    while !c.done() {
        match c.word("a key")? {
            "scale" => scale = c.pos_num("scale")?,
            k => return Err(format!("unknown environment key '{k}' (scale)")),
        }
    }
    emitter(s, scale)
}

struct Builder<'p> {
    materials: Vec<Material>,
    names: HashMap<String, usize>,
    objects: Vec<(Vec<Prim>, usize)>,
    environment: Option<(Spectrum, f32)>,
    camera: Option<Camera>,
    dir: Option<&'p Path>,
}

impl Builder<'_> {
    fn statement(&mut self, c: &mut Cursor) -> Res<()> {
        let head = c.word("a statement")?;
        match head {
            "camera" => self.camera = Some(camera(c)?),
            "environment" => self.environment = Some(environment(c)?),
            "material" => {
                let name = c.word("a material name")?;
                if self.names.contains_key(name) {
                    return Err(format!("material '{name}' is defined twice"));
                }
                let m = self.material(c)?;
                self.names.insert(name.to_string(), self.materials.len());
                self.materials.push(m);
            }
            "sphere" | "quad" | "box" | "prism" | "torus" | "mesh" => {
                let keys = self.shape_keys(head, c)?;
                let material = keys
                    .material
                    .ok_or_else(|| format!("{head} needs 'material'"))?;
                let prims = self.shape(head, &keys)?;
                self.objects.push((prims, material));
            }
            h => {
                return Err(format!(
                    "unknown statement '{h}' (camera, environment, material, sphere, quad, box, prism, torus, mesh)"
                ))
            }
        }
        Ok(())
    }

    /// Reads a shape statement's keys; each key has a fixed number of values.
    fn shape_keys<'a>(&self, head: &str, c: &mut Cursor<'a>) -> Res<ShapeKeys<'a>> {
        let mut keys = ShapeKeys {
            values: HashMap::new(),
            material: None,
            file: None,
        };
        while !c.done() {
            let key = c.word("a key")?;
            let arity = match (head, key) {
                (_, "material") => {
                    let n = c.word("a material name")?;
                    keys.material = Some(
                        *self
                            .names
                            .get(n)
                            .ok_or_else(|| format!("unknown material '{n}'"))?,
                    );
                    continue;
                }
                ("mesh", "file") => {
                    keys.file = Some(c.word("a file name")?);
                    continue;
                }
                ("sphere", "center") | ("prism", "center") | ("torus", "center") => 3,
                ("sphere", "radius") => 1,
                ("quad", "corner" | "edge1" | "edge2") => 3,
                ("box", "min" | "max") => 3,
                ("prism", "size" | "height") => 1,
                ("torus", "radii") => 2,
                ("mesh", "translate") => 3,
                ("mesh", "scale") => 1,
                ("box" | "prism" | "mesh", "rotate") | ("torus", "tilt") => 1,
                _ => return Err(format!("unknown {head} key '{key}'")),
            };
            let vals = (0..arity).map(|_| c.num(key)).collect::<Res<Vec<f32>>>()?;
            if keys.values.insert(key, vals).is_some() {
                return Err(format!("'{key}' given twice"));
            }
        }
        Ok(keys)
    }

    /// The primitives of a shape statement whose keys are read.
    fn shape(&self, head: &str, keys: &ShapeKeys) -> Res<Vec<Prim>> {
        let get = |k: &str| keys.get(head, k);
        let opt = |k: &str, d: f32| keys.values.get(k).map_or(d, |v| v[0]);
        Ok(match head {
            "sphere" => vec![Prim::Sphere {
                c: v3(get("center")?),
                r: positive(get("radius")?[0], "radius")?,
            }],
            "quad" => {
                let (e1, e2) = (v3(get("edge1")?), v3(get("edge2")?));
                if e1.cross(e2).len() <= 0.0 {
                    return Err("quad edges are parallel".into());
                }
                vec![Prim::Quad {
                    p: v3(get("corner")?),
                    e1,
                    e2,
                }]
            }
            "box" => {
                let (lo, hi) = (v3(get("min")?), v3(get("max")?));
                if !(lo.0 < hi.0 && lo.1 < hi.1 && lo.2 < hi.2) {
                    return Err("box min must be below max on every axis".into());
                }
                boxed(lo, hi, opt("rotate", 0.0))
            }
            "prism" => prism(
                v3(get("center")?),
                positive(get("size")?[0], "size")?,
                positive(get("height")?[0], "height")?,
                opt("rotate", 0.0),
            ),
            "torus" => {
                let r = get("radii")?;
                if !(r[0] > r[1] && r[1] > 0.0) {
                    return Err("torus radii must satisfy MAJOR > MINOR > 0".into());
                }
                torus(v3(get("center")?), r[0], r[1], opt("tilt", 0.0))
            }
            _ => self.mesh(keys, &opt)?,
        })
    }

    /// A mesh statement's triangles: the OBJ file next to the scene file, scaled, turned
    /// and moved.
    fn mesh(&self, keys: &ShapeKeys, opt: &dyn Fn(&str, f32) -> f32) -> Res<Vec<Prim>> {
        let file = keys.file.ok_or("mesh needs 'file'")?;
        let dir = self
            .dir
            .ok_or("mesh files need the scene to come from a file")?;
        let path = dir.join(file);
        let text =
            std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let tris = obj::parse(&text, &path.display().to_string())?;
        let s = positive(opt("scale", 1.0), "scale")?;
        let rot = opt("rotate", 0.0);
        let t = keys
            .values
            .get("translate")
            .cloned()
            .map_or(V3::default(), v3);
        let xf = |p: V3| rotate_y(p * s, rot) + t;
        Ok(tris
            .into_iter()
            .map(|p| match p {
                Prim::Triangle { p0, e1, e2 } => {
                    let a = xf(p0);
                    Prim::Triangle {
                        p0: a,
                        e1: xf(p0 + e1) - a,
                        e2: xf(p0 + e2) - a,
                    }
                }
                p => p,
            })
            .collect())
    }

    fn material(&mut self, c: &mut Cursor) -> Res<Material> {
        let kind = c.word("a material kind")?;
        let mut m = MaterialKeys::default();
        if kind == "emitter" {
            m.spectrum = Some(c.spectrum(EMISSION)?);
        }
        while !c.done() {
            m.key(kind, c)?;
        }
        m.build(kind)
    }
}

/// The keys a material statement has given so far.
struct MaterialKeys {
    reflectance: Option<Reflectance>,
    roughness: Texture,
    distribution: Distribution,
    ior: Option<Ior>,
    metal: Option<Metal>,
    eta: Option<Spectrum>,
    k: Option<Spectrum>,
    spectrum: Option<Spectrum>,
    scale: f32,
    two_sided: bool,
}

impl Default for MaterialKeys {
    fn default() -> Self {
        MaterialKeys {
            reflectance: None,
            roughness: Texture::scalar(0.0),
            distribution: Distribution::Ggx,
            ior: None,
            metal: None,
            eta: None,
            k: None,
            spectrum: None,
            scale: 1.0,
            two_sided: false,
        }
    }
}

impl MaterialKeys {
    /// Reads one key of a `kind` material and its values.
    fn key(&mut self, kind: &str, c: &mut Cursor) -> Res<()> {
        match (kind, c.word("a key")?) {
            ("diffuse" | "plastic", "reflectance") => self.reflectance = Some(c.reflectance()?),
            ("conductor" | "dielectric" | "plastic", "roughness") => {
                self.roughness = c.scalar_texture(0.0, 1.0)?
            }
            ("conductor" | "dielectric", "distribution") => {
                self.distribution = match c.word("a distribution")? {
                    "ggx" => Distribution::Ggx,
                    "beckmann" => Distribution::Beckmann,
                    d => return Err(format!("unknown distribution '{d}' (ggx, beckmann)")),
                }
            }
            ("conductor", "metal") => {
                let n = c.word("a metal")?;
                self.metal =
                    Some(metal(n).ok_or_else(|| format!("unknown metal '{n}' (Au, Ag, Cu, Al)"))?);
            }
            ("conductor", "eta") => self.eta = Some(c.spectrum((0.0, 100.0))?),
            ("conductor", "k") => self.k = Some(c.spectrum((0.0, 100.0))?),
            ("dielectric" | "plastic", "ior") => {
                self.ior = Some(if c.next_is_num() {
                    let n = c.num("ior")?;
                    if !(1.0..=4.0).contains(&n) {
                        return Err(format!("ior {n} is outside 1..4"));
                    }
                    Ior::Constant(n)
                } else if kind == "dielectric" {
                    Ior::Tabulated(c.spectrum((1.0, 4.0))?)
                } else {
                    return Err("a plastic's ior is one number".into());
                })
            }
            ("dielectric", "cauchy") => {
                self.ior = Some(Ior::Cauchy {
                    a: c.pos_num("cauchy A")?,
                    b: c.num("cauchy B")?,
                })
            }
            ("dielectric", "sellmeier") => self.ior = Some(sellmeier(c)?),
            ("emitter", "scale") => self.scale = c.pos_num("scale")?,
            ("emitter", "two-sided") => self.two_sided = true,
            (_, k) => return Err(format!("unknown key '{k}' for a {kind} material")),
        }
        Ok(())
    }

    /// The material the keys describe.
    fn build(self, kind: &str) -> Res<Material> {
        if let Some(i) = &self.ior {
            for l in [380.0, 580.0, 780.0] {
                let n = i.eval(l);
                if !(n.is_finite() && (1.0..=4.0).contains(&n)) {
                    return Err(format!("ior evaluates to {n} at {l} nm"));
                }
            }
        }
        Ok(match kind {
            "diffuse" => Material::Diffuse {
                reflectance: self.reflectance.ok_or("diffuse needs 'reflectance'")?,
            },
            "conductor" => {
                let m = match (self.metal, self.eta, self.k) {
                    (Some(m), None, None) => m,
                    (None, Some(eta), Some(k)) => Metal { eta, k },
                    _ => return Err("conductor needs either 'metal' or both 'eta' and 'k'".into()),
                };
                Material::Conductor {
                    albedo: metal_albedo(&m),
                    metal: m,
                    roughness: self.roughness,
                    distribution: self.distribution,
                }
            }
            "dielectric" => Material::Dielectric {
                ior: self
                    .ior
                    .ok_or("dielectric needs 'ior', 'cauchy' or 'sellmeier'")?,
                roughness: self.roughness,
                distribution: self.distribution,
            },
            "plastic" => Material::Plastic {
                reflectance: self.reflectance.ok_or("plastic needs 'reflectance'")?,
                ior: match self.ior {
                    Some(Ior::Constant(n)) => n,
                    _ => 1.5,
                },
                roughness: self.roughness,
            },
            "emitter" => {
                let (radiance, scale) = emitter(self.spectrum.expect("read first"), self.scale)?;
                Material::Emitter {
                    radiance,
                    scale,
                    two_sided: self.two_sided,
                }
            }
            k => {
                return Err(format!(
                    "unknown material kind '{k}' (diffuse, conductor, dielectric, plastic, emitter)"
                ))
            }
        })
    }
}

/// A Sellmeier glass: six coefficients or a catalogue name.
fn sellmeier(c: &mut Cursor) -> Res<Ior> {
    if !c.next_is_num() {
        return match c.word("a glass name")? {
            "bk7" => Ok(BK7),
            "sf11" => Ok(SF11),
            g => Err(format!("unknown glass '{g}' (bk7, sf11)")),
        };
    }
    let mut b = [0.0; 3];
    let mut cc = [0.0; 3];
    for v in &mut b {
        *v = c.num("a Sellmeier B")?;
    }
    for v in &mut cc {
        *v = c.num("a Sellmeier C")?;
    }
    Ok(Ior::Sellmeier { b, c: cc })
}

/// Parses scene text. `name` names the scene and prefixes errors; `dir` is where mesh
/// paths are resolved (None: meshes are refused).
pub fn parse(text: &str, name: &str, dir: Option<&Path>) -> Result<Scene, String> {
    let mut b = Builder {
        materials: Vec::new(),
        names: HashMap::new(),
        objects: Vec::new(),
        environment: None,
        camera: None,
        dir,
    };
    for (ln, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("");
        let mut c = Cursor {
            toks: line.split_whitespace().collect(),
            pos: 0,
            dir,
        };
        if c.done() {
            continue;
        }
        b.statement(&mut c)
            .map_err(|e| format!("{name}:{}: {e}", ln + 1))?;
    }
    let camera = b.camera.ok_or(format!("{name}: no 'camera' statement"))?;
    if b.objects.is_empty() {
        return Err(format!("{name}: no shapes"));
    }
    let lit = b.environment.is_some()
        || b.objects
            .iter()
            .any(|(_, m)| matches!(b.materials[*m], Material::Emitter { .. }));
    if !lit {
        return Err(format!(
            "{name}: nothing emits light (add an emitter material or an environment)"
        ));
    }
    Ok(Scene::new(
        name,
        b.materials,
        b.objects,
        b.environment,
        camera,
    ))
}

/// Reads a scene file; its mesh paths resolve next to it.
pub fn load(path: &Path) -> Result<Scene, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let name = path
        .file_stem()
        .map_or("scene".into(), |s| s.to_string_lossy().into_owned());
    parse(&text, &name, path.parent())
        .map_err(|e| e.replacen(&name, &path.display().to_string(), 1))
}

#[cfg(test)]
mod tests {
    use super::*;

    const OK: &str = "camera eye 0 1 -3 target 0 0 0 fov 40\n\
        material w diffuse reflectance checker 0.8 0.8 0.8 0.1 0.1 0.1 4\n\
        material l emitter blackbody 4000 scale 10\n\
        sphere center 0 0 0 radius 1 material w\n\
        quad corner -1 2 -1 edge1 2 0 0 edge2 0 0 2 material l\n";

    #[test]
    fn parses_a_small_scene() {
        let s = parse(OK, "ok", None).unwrap();
        assert_eq!(s.prims.len(), 2);
        assert_eq!(s.lights().len(), 1);
    }

    #[test]
    fn distribution_defaults_to_ggx() {
        let text = format!(
            "{OK}material a conductor metal Au roughness 0.2\n\
             material b conductor metal Au roughness 0.2 distribution beckmann\n\
             material c dielectric ior 1.5 roughness 0.2 distribution beckmann\n\
             material d dielectric ior 1.5 distribution ggx\n"
        );
        let s = parse(&text, "ok", None).unwrap();
        let dist = |i: usize| match &s.materials[i] {
            Material::Conductor { distribution, .. }
            | Material::Dielectric { distribution, .. } => *distribution,
            _ => panic!("material {i}"),
        };
        let n = s.materials.len();
        assert_eq!(dist(n - 4), Distribution::Ggx);
        assert_eq!(dist(n - 3), Distribution::Beckmann);
        assert_eq!(dist(n - 2), Distribution::Beckmann);
        assert_eq!(dist(n - 1), Distribution::Ggx);
    }

    #[test]
    fn errors_name_the_line() {
        let cases = [
            ("camera eye 0 0 0 target 0 0 1\nmaterial w diffuse reflectance rgb 2 0 0\n", 2, "[0, 1]"),
            ("camera eye 0 0 0 target 0 0 1\nsphere center 0 0 0 radius 1 material nope\n", 2, "unknown material"),
            ("camera eye 0 0 0 target 0 0 1\n\n# c\nfoo bar\n", 4, "unknown statement"),
            ("camera eye 0 0 x target 0 0 1\n", 1, "expected a number"),
            ("camera eye 0 0 0 target 0 0 1\nmaterial g dielectric sellmeier crown\n", 2, "unknown glass"),
            ("camera eye 0 0 0 target 0 0 1\nmaterial m conductor metal Fe\n", 2, "unknown metal"),
            ("camera eye 0 0 0 target 0 0 1\nmaterial l emitter laser 900\n", 2, "380..780"),
            ("camera eye 0 0 0 target 0 0 1\nmaterial m conductor metal Au distribution phong\n", 2, "unknown distribution"),
            ("camera eye 0 0 0 target 0 0 1\nmaterial w diffuse reflectance rgb 1 1 1 distribution ggx\n", 2, "unknown key"),
            ("camera eye 0 0 0 target 0 0 1\nmaterial w diffuse reflectance rgb 1 1 1\nsphere center 0 0 0 material w\n", 3, "needs 'radius'"),
        ];
        for (text, line, msg) in cases {
            let e = parse(text, "t.scene", None).unwrap_err();
            assert!(
                e.starts_with(&format!("t.scene:{line}:")) && e.contains(msg),
                "{e}"
            );
        }
        let e = parse("camera eye 0 0 0 target 0 0 1\n", "t", None).unwrap_err();
        assert!(e.contains("no shapes"), "{e}");
    }

    #[test]
    fn measured_spectra_and_one_sided_lamps_are_written_directly() {
        let text = format!(
            "{OK}material line emitter table 540 0.01 546 5 552 0.01 scale 3\n\
             material both emitter d65 two-sided\n\
             material gold conductor eta table 400 1.5 700 0.2 k constant 3 roughness 0.1\n\
             material glass dielectric ior table 400 1.53 700 1.51\n\
             material paint diffuse reflectance spectrum table 400 0.1 700 0.9\n"
        );
        let s = parse(&text, "ok", None).unwrap();
        let m = |i: usize| &s.materials[i];
        assert!(matches!(
            m(1),
            Material::Emitter {
                two_sided: false,
                ..
            }
        ));
        assert!(
            matches!(m(2), Material::Emitter { radiance, two_sided: false, .. } if radiance.is_spiky())
        );
        assert!(matches!(
            m(3),
            Material::Emitter {
                two_sided: true,
                ..
            }
        ));
        assert!(
            matches!(m(4), Material::Conductor { metal, .. } if (metal.eta.eval(550.0) - 0.85).abs() < 1e-5)
        );
        assert!(matches!(m(5), Material::Dielectric { ior, .. } if ior.dispersive()));
        let Material::Diffuse {
            reflectance: Reflectance::Spectral { rgb, .. },
        } = m(6)
        else {
            panic!("a spectral reflectance")
        };
        assert!(
            rgb[0] > rgb[2],
            "a reflectance rising to the red looks red: {rgb:?}"
        );
        for (line, msg) in [
            ("material x emitter table 500 1\n", "at least two"),
            ("material x emitter table 500 1 400 1\n", "must increase"),
            (
                "material p diffuse reflectance spectrum table 400 0.5 500 1.5\n",
                "outside 0..1",
            ),
            (
                "material c conductor eta constant 1\n",
                "both 'eta' and 'k'",
            ),
            (
                "material x emitter csv lamp.csv\n",
                "scene to come from a file",
            ),
        ] {
            let e = parse(&format!("{OK}{line}"), "t.scene", None).unwrap_err();
            assert!(e.starts_with("t.scene:6:") && e.contains(msg), "{e}");
        }
    }

    #[test]
    fn csv_spectra_load_relative_to_the_scene_and_name_their_lines() {
        let dir = std::env::temp_dir().join(format!("temc-render-csv-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(
            dir.join("lamp.csv"),
            "# a lamp\nnm,value\n400, 0.5\n500;1\n600 0.5\n",
        )
        .unwrap();
        std::fs::write(dir.join("bad.csv"), "nm,value\n400,0.5\n500,x\n").unwrap();
        let scene = format!("{OK}material c emitter csv lamp.csv scale 2\n");
        std::fs::write(dir.join("c.scene"), &scene).unwrap();
        let s = load(&dir.join("c.scene")).unwrap();
        let Material::Emitter { radiance, .. } = &s.materials[2] else {
            panic!("an emitter")
        };
        assert!((radiance.eval(450.0) - 0.75).abs() < 1e-6);
        std::fs::write(dir.join("b.scene"), scene.replace("lamp.csv", "bad.csv")).unwrap();
        let e = load(&dir.join("b.scene")).unwrap_err();
        assert!(e.contains("b.scene:6:") && e.contains("bad.csv:3:"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn meshes_load_relative_to_the_scene_file() {
        let dir = std::env::temp_dir().join(format!("temc-render-mesh-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        let scene = format!("{OK}mesh file tri.obj scale 2 translate 0 0 1 material w\n");
        std::fs::write(dir.join("m.scene"), &scene).unwrap();
        let s = load(&dir.join("m.scene")).unwrap();
        assert_eq!(s.prims.len(), 3);
        std::fs::write(dir.join("bad.scene"), scene.replace("tri.obj", "nope.obj")).unwrap();
        let e = load(&dir.join("bad.scene")).unwrap_err();
        assert!(e.contains("bad.scene:6:"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
