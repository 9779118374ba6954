//! `temc-render dataset`: noisy/reference pairs from generated scenes, split by scene into
//! train/validation/test, resumable (a scene is done when its `done.json` exists; every
//! file is written atomically), with its cost recorded.
//!
//! Layout (what `training/` reads):
//!
//! ```text
//! DIR/dataset.json                 the settings; a resumed run must match them
//! DIR/manifest.json                every finished scene, its files, seconds, sampling and
//!                                  family; totals
//! DIR/manifest.part-I-of-N.json    the same for part I of N (`--part`, see `part.rs`),
//!                                  until `merge-manifests` joins the parts into it
//! DIR/{train,val,test}/NAME/scene.txt   the scene file (re-renderable)
//! DIR/{train,val,test}/NAME/spp0004.exr ... one multi-layer EXR per noisy spp
//! DIR/{train,val,test}/NAME/ref.exr      the reference (independent seed)
//! DIR/{train,val,test}/NAME/done.json    the scene's record (written last)
//! ```
//!
//! Test scenes come in three kinds: `named-*` (the hand-written stress scenes), `holdout-*`
//! (the held-out families of `description::held_out`, never in train or val) and the
//! generator's `scene-*` on seeds of the test split.
//!
//! Noisy images at several spp come from one progressive render (each is a prefix of the
//! next); the reference uses its own seed, so its noise is independent of theirs. With
//! `--weak-share F` a share F of the generated scenes render their noisy images with a
//! weaker sampler ([`weak_sampling`]), so a model also sees the noise of renderers that
//! sample worse; references always use the tracer's own sampler. With `--families all`
//! the generated scenes come from every family of `description::families` (sun and sky,
//! many small lights, glossy interiors, caustics, fine textures) instead of the `v2`
//! rooms and open floors alone; each scene's record names its family.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use serde::{Deserialize, Serialize};
use temc_render::description::families::{self, Families};
use temc_render::description::{format, held_out, named};
use temc_render::output::{write_bytes_atomic, write_bytes_atomic_tagged};
use temc_render::rng::splitmix;
use temc_render::{render_progressive, Sampling, Settings};

use crate::part::Part;

/// `temc-render dataset`'s options.
#[derive(clap::Args)]
pub struct Args {
    /// Generated scenes.
    #[arg(long, default_value_t = 100)]
    count: usize,
    /// Image width and height.
    #[arg(long, default_value_t = 256)]
    size: usize,
    /// Noisy sample counts, comma-separated.
    #[arg(long, default_value = "4,16,64,256", value_delimiter = ',')]
    spp: Vec<u32>,
    /// Reference sample count.
    #[arg(long, default_value_t = 4096)]
    ref_spp: u32,
    /// Also write the reference render at these sample counts (noisy targets for
    /// Noise2Noise training), comma-separated.
    #[arg(long, value_delimiter = ',')]
    ref_prefix_spp: Vec<u32>,
    /// Base seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Leave out the named stress scenes (otherwise rendered into the test split).
    #[arg(long)]
    no_named: bool,
    /// Scenes per held-out family (`temc-render generate --family`), rendered into the test
    /// split only as `holdout-FAMILY-NNN`: layouts and lighting no training scene has.
    #[arg(long, default_value_t = 6)]
    holdout: usize,
    /// Render the generated scenes from this index on (wrapping round to 0): sessions on
    /// fresh machines that each render a part of the set then cover different scenes. The
    /// set, its scenes and their splits do not depend on it.
    #[arg(long, default_value_t = 0)]
    start: usize,
    /// Render only part I of N (1-based: 1/N to N/N) of the set, for a cluster: every
    /// N-th scene of the set's fixed order, each exactly as a whole run renders it, listed
    /// in `manifest.part-I-of-N.json`. Parts may share one --out; when all have finished,
    /// `temc-render merge-manifests --out DIR` writes the set's manifest.json.
    #[arg(long, value_name = "I/N")]
    part: Option<Part>,
    /// Share (0 to 1) of the generated scenes whose noisy images render with a randomly
    /// chosen combination of the weak sampling modes (`render --sampling`), imitating
    /// other renderers' noise; chosen by a hash of the seed and the scene's index, and
    /// recorded in each scene's record. References always use the default sampler.
    #[arg(long, default_value_t = 0.0, value_name = "F")]
    weak_share: f64,
    /// The families of the generated scenes: v2 (a room or an open floor: the spectral-v2
    /// set, unchanged) or all (also sun-sky, small-lights, glossy-interior,
    /// caustic-fireflies and fine-texture; one per scene by a hash of its seed).
    #[arg(long, default_value = "v2", value_name = "v2|all")]
    families: Families,
    /// Render only the scenes of this split (train, val or test), each exactly as a whole
    /// run renders it: a test split alone, for measuring shipped models, costs about an
    /// eighth of the set. The manifest lists what has been rendered; a later run without
    /// the option renders the rest into the same folder.
    #[arg(long, value_parser = ["train", "val", "test"])]
    split: Option<String>,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
}

/// Renders the data set with a progress bar and prints its cost.
pub fn main(a: Args, cancel: &AtomicBool) -> Result<(), String> {
    let opts = Options {
        count: a.count,
        size: a.size,
        spp: a.spp,
        ref_spp: a.ref_spp,
        seed: a.seed,
        named: !a.no_named,
        holdout: a.holdout,
        ref_prefix_spp: a.ref_prefix_spp,
        start: a.start,
        weak_share: a.weak_share,
        families: a.families,
        only_split: a.split,
    };
    let (size, out, part) = (a.size, a.out, a.part);
    let t = Instant::now();
    let b = crate::bar(size as u64);
    let m = run(
        &opts,
        &out,
        part,
        &|line| {
            if b.is_hidden() {
                eprintln!("{line}");
            } else {
                b.println(line);
            }
        },
        &|rows| b.set_position(rows as u64 % (size as u64 + 1)),
        cancel,
    )?;
    b.finish_and_clear();
    let n = m.scenes.len().max(1) as f64;
    let which = part.map_or(String::new(), |p| format!("part {p}: "));
    eprintln!(
        "temc-render: {which}{} scenes in {} ({:.0} s this run). Render cost: noisy {:.0} s ({:.1} s/scene), references {:.0} s ({:.1} s/scene).",
        m.scenes.len(),
        out.display(),
        t.elapsed().as_secs_f64(),
        m.seconds_noisy,
        m.seconds_noisy / n,
        m.seconds_reference,
        m.seconds_reference / n
    );
    if let Some(p) = part {
        eprintln!(
            "temc-render: once every part of {} has finished: temc-render merge-manifests --out {}",
            p.count,
            out.display()
        );
    }
    Ok(())
}

/// What to render.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Options {
    /// Generated scenes.
    pub count: usize,
    /// Image width and height.
    pub size: usize,
    /// Noisy sample counts.
    pub spp: Vec<u32>,
    /// Reference sample count.
    pub ref_spp: u32,
    /// Base seed of the scene generator and the renders.
    pub seed: u64,
    /// Also render the named stress scenes into the test split.
    pub named: bool,
    /// Scenes per held-out family, test split only. May grow on resume, like `count`; 0 in
    /// data sets made before the families existed.
    #[serde(default)]
    pub holdout: usize,
    /// Sample counts at which a prefix of the reference render is also written
    /// (`ref-sppNNNN.exr`): noisy targets, independent of the inputs, for Noise2Noise
    /// training at a fraction of the reference's cost. Empty in data sets made before.
    #[serde(default)]
    pub ref_prefix_spp: Vec<u32>,
    /// Order of work only: the generated scenes are rendered from this index on, wrapping.
    /// Not recorded (a resumed set may start elsewhere).
    #[serde(skip)]
    pub start: usize,
    /// Share of the generated scenes whose noisy images use a weak sampling mode (see
    /// [`weak_sampling`]). Not written when 0, so the settings of a set without weak
    /// scenes read as they did before the option, and absent (0) in those sets.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub weak_share: f64,
    /// The families of the generated scenes. Not written when `v2`, so the settings of a
    /// `v2` set read as they did before the option, and absent (`v2`) in those sets.
    #[serde(default, skip_serializing_if = "is_v2", with = "families_text")]
    pub families: Families,
    /// Which scenes to render, not which the set has: only this split's (`--split`), or
    /// all. Not recorded, like `start`.
    #[serde(skip)]
    pub only_split: Option<String>,
}

/// Whether `f` is `v2` (for serde: not written).
fn is_v2(f: &Families) -> bool {
    *f == Families::V2
}

/// [`Families`] as its text ("v2", "all") in `dataset.json`.
mod families_text {
    use serde::{Deserialize, Deserializer, Serializer};
    use temc_render::description::families::Families;

    /// Writes the text.
    pub fn serialize<S: Serializer>(f: &Families, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(f)
    }

    /// Reads the text.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Families, D::Error> {
        String::deserialize(d)?
            .parse()
            .map_err(serde::de::Error::custom)
    }
}

/// Whether `v` is 0 (for serde: a weak share of 0 is not written).
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// One finished scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Record {
    /// Scene name (directory name).
    pub name: String,
    /// "train", "val" or "test".
    pub split: String,
    /// Directory relative to the data set root.
    pub dir: String,
    /// Noisy files by spp.
    pub noisy: Vec<(u32, String)>,
    /// Reference file.
    pub reference: String,
    /// Prefixes of the reference render by spp (see [`Options::ref_prefix_spp`]).
    #[serde(default)]
    pub reference_prefixes: Vec<(u32, String)>,
    /// Seconds for the noisy progressive render and for the reference.
    pub seconds_noisy: f64,
    /// Seconds for the reference.
    pub seconds_reference: f64,
    /// The scene's features (what the kernel simulated).
    pub features: String,
    /// The sampling mode of the noisy images: "default", or weak modes such as
    /// "bsdf-only,uniform-wavelength" (`--weak-share`). "default" in sets made before.
    #[serde(default = "default_sampling")]
    pub sampling: String,
    /// The scene's family: "room", "open" or another of `description::families` for a
    /// generated scene, "window" or "corridor" for a held-out one, "named" for the named
    /// stress scenes. Absent from records written before; a resumed run fills it in.
    #[serde(default)]
    pub family: String,
}

/// The sampling mode of records written before the modes existed.
fn default_sampling() -> String {
    Sampling::DEFAULT.to_string()
}

/// The data set's summary, written as `manifest.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Manifest {
    /// Settings.
    pub options: Options,
    /// Layers in every EXR.
    pub layers: Vec<String>,
    /// Finished scenes.
    pub scenes: Vec<Record>,
    /// Total render seconds, noisy.
    pub seconds_noisy: f64,
    /// Total render seconds, references.
    pub seconds_reference: f64,
    /// How many finished scenes rendered their noisy images with each sampling mode
    /// ([`Record::sampling`]).
    #[serde(default)]
    pub sampling: BTreeMap<String, usize>,
    /// How many finished scenes belong to each family ([`Record::family`]).
    #[serde(default)]
    pub families: BTreeMap<String, usize>,
    /// In a part's manifest (`--part`), which part; absent from the whole set's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub part: Option<PartOf>,
}

/// Where a part's manifest belongs: what `merge-manifests` needs that [`Options`] does not
/// record.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct PartOf {
    /// The part, 1..=count.
    pub index: usize,
    /// The number of parts.
    pub count: usize,
    /// The `--start` it was rendered with: the merged manifest lists the scenes in the
    /// order a whole run with that start would.
    pub start: usize,
}

impl Manifest {
    /// The manifest of `records`, with their total seconds.
    pub fn new(opts: &Options, records: Vec<Record>, part: Option<PartOf>) -> Manifest {
        Manifest {
            options: opts.clone(),
            layers: temc_color::layers::channel_names(),
            seconds_noisy: records.iter().map(|r| r.seconds_noisy).sum(),
            seconds_reference: records.iter().map(|r| r.seconds_reference).sum(),
            sampling: count_by(&records, |r| &r.sampling),
            families: count_by(&records, |r| &r.family),
            scenes: records,
            part,
        }
    }

    /// Writes it as `name` in `out`.
    pub fn write(&self, out: &Path, name: &str) -> Result<(), String> {
        write_bytes_atomic(
            &out.join(name),
            serde_json::to_string_pretty(self).unwrap().as_bytes(),
        )
    }
}

/// How many of `records` have each value of `key`.
fn count_by(records: &[Record], key: impl Fn(&Record) -> &String) -> BTreeMap<String, usize> {
    records.iter().fold(BTreeMap::new(), |mut n, r| {
        *n.entry(key(r).clone()).or_insert(0) += 1;
        n
    })
}

/// One scene of the set: what to render and where.
#[derive(Clone, Debug, PartialEq)]
pub struct Job {
    /// Its place in the set's fixed order (the order at `--start 0`), which decides its part.
    pub index: usize,
    /// Scene name (directory name).
    pub name: String,
    /// "train", "val" or "test".
    pub split: &'static str,
    /// The scene file.
    pub text: String,
    /// The sampling mode of its noisy images.
    pub sampling: Sampling,
    /// Its family ([`Record::family`]).
    pub family: &'static str,
}

/// Which split a generated scene belongs to: 80 % train, 10 % validation, 10 % test,
/// decided by a hash of its index so growing `count` keeps earlier assignments.
pub fn split_of(index: usize) -> &'static str {
    let mut h = (index as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    h ^= h >> 29;
    match h % 10 {
        8 => "val",
        9 => "test",
        _ => "train",
    }
}

/// The sampling mode of generated scene `index`'s noisy images. A share
/// [`Options::weak_share`] of the scenes, picked by a hash of the base seed and the index
/// (so growing `count` keeps every earlier choice, and a larger share keeps the scenes a
/// smaller one picked), gets one of [`Sampling::weak_combinations`], chosen by a second
/// hash; the rest the tracer's own sampler.
pub fn weak_sampling(opts: &Options, index: usize) -> Sampling {
    let h = splitmix(opts.seed ^ splitmix(index as u64));
    let u = (h >> 11) as f64 / (1u64 << 53) as f64;
    if u >= opts.weak_share {
        return Sampling::DEFAULT;
    }
    let weak = Sampling::weak_combinations();
    weak[(splitmix(h) % weak.len() as u64) as usize]
}

/// Renders the data set, or with `part` only that part of it; `log` gets one line per
/// scene. Returns the manifest (the part's, for a part).
pub fn run(
    opts: &Options,
    out: &Path,
    part: Option<Part>,
    log: &dyn Fn(&str),
    progress: &(dyn Fn(usize) + Sync),
    cancel: &AtomicBool,
) -> Result<Manifest, String> {
    if opts.spp.is_empty() || opts.spp.contains(&0) || opts.ref_spp == 0 || opts.size < 8 {
        return Err("need --spp values > 0, --ref-spp > 0 and --size >= 8".into());
    }
    if !(0.0..=1.0).contains(&opts.weak_share) {
        return Err(format!(
            "--weak-share {}: expected a share from 0 to 1",
            opts.weak_share
        ));
    }
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    check_settings(opts, out, part)?;
    let jobs: Vec<Job> = jobs(opts)
        .into_iter()
        .filter(|j| part.is_none_or(|p| p.contains(j.index)))
        .filter(|j| opts.only_split.as_ref().is_none_or(|s| s == j.split))
        .collect();
    // Every finished scene is in the manifest before the first new one renders: training
    // reads the manifest while the set grows, and a resumed set must not look empty.
    let done = |job: &Job| out.join(job.split).join(&job.name).join("done.json");
    let finished = |job| {
        std::fs::read_to_string(done(job))
            .ok()
            .and_then(|t| serde_json::from_str::<Record>(&t).ok())
    };
    let mut todo = Vec::new();
    let mut records = Vec::new();
    for (k, job) in jobs.iter().enumerate() {
        match finished(job) {
            Some(mut r) => {
                // Records from before the families name theirs from the job.
                if r.family.is_empty() {
                    r.family = job.family.to_string();
                }
                records.push(r)
            }
            None => todo.push(k),
        }
    }
    let write = |records: &[Record]| write_manifest(opts, out, part, records);
    write(&records)?;
    for k in todo {
        let job = &jobs[k];
        let r = render_scene(opts, out, job, progress, cancel)?;
        write_bytes_atomic(
            &done(job),
            serde_json::to_string_pretty(&r).unwrap().as_bytes(),
        )?;
        let weak = if job.sampling.is_default() {
            String::new()
        } else {
            format!(", sampling {}", job.sampling)
        };
        log(&format!(
            "{}/{}: {}/{} ({}{weak}): noisy {:.1} s, reference {:.1} s",
            k + 1,
            jobs.len(),
            job.split,
            job.name,
            job.family,
            r.seconds_noisy,
            r.seconds_reference
        ));
        records.push(r);
        write(&records)?;
    }
    write(&records)
}

/// Refuses to resume a data set made with other settings (the scene count may grow), then
/// records these. Every part of a cluster render writes the same settings into the shared
/// folder, so a part's temporary file carries its part: process ids on different
/// machines may coincide.
fn check_settings(opts: &Options, out: &Path, part: Option<Part>) -> Result<(), String> {
    let settings_path = out.join("dataset.json");
    if settings_path.exists() {
        let old: Options = serde_json::from_str(
            &std::fs::read_to_string(&settings_path).map_err(|e| e.to_string())?,
        )
        .map_err(|e| format!("{}: {e}", settings_path.display()))?;
        let same = Options {
            count: old.count,
            holdout: old.holdout,
            start: old.start,
            only_split: old.only_split.clone(),
            ..opts.clone()
        } == old;
        if !same {
            return Err(format!(
                "{} was made with other settings ({old:?}); use another --out",
                out.display()
            ));
        }
    }
    let tag = part.map_or(String::new(), |p| {
        format!("part-{}-of-{}", p.index, p.count)
    });
    write_bytes_atomic_tagged(
        &settings_path,
        &tag,
        serde_json::to_string_pretty(opts).unwrap().as_bytes(),
    )
}

/// The scenes to render, in order. The named stress scenes come first, so the test
/// split's hard cases are ready early, then the held-out families' scenes; then the
/// generated ones from index `start`, wrapping. A scene's [`Job::index`] is its place at
/// `start` 0.
pub fn jobs(opts: &Options) -> Vec<Job> {
    let mut jobs = Vec::new();
    let mut push = |name: String, split, (family, text): (&'static str, String), sampling| {
        let index = jobs.len();
        jobs.push(Job {
            index,
            name,
            split,
            text,
            sampling,
            family,
        });
    };
    // The named and held-out test scenes keep the tracer's own sampler: their scores stay
    // comparable with sets made before the weak modes.
    let own = Sampling::DEFAULT;
    if opts.named {
        for (name, _, text) in named::NAMED {
            if name != "furnace" {
                let scene = ("named", text.to_string());
                push(format!("named-{name}"), "test", scene, own);
            }
        }
    }
    for family in held_out::FAMILIES {
        for k in 0..opts.holdout {
            let seed = opts.seed.wrapping_mul(1_000_003).wrapping_add(k as u64);
            let text = held_out::scene_text(family, seed).expect("a listed family");
            push(
                format!("holdout-{family}-{k:03}"),
                "test",
                (family, text),
                own,
            );
        }
    }
    for i in 0..opts.count {
        let seed = opts.seed.wrapping_mul(1_000_003).wrapping_add(i as u64);
        push(
            format!("scene-{i:05}"),
            split_of(i),
            families::scene(opts.families, seed),
            weak_sampling(opts, i),
        );
    }
    // The generated scenes come last, so rotating the tail rotates them alone.
    let generated = jobs.len() - opts.count;
    jobs[generated..].rotate_left(opts.start.checked_rem(opts.count).unwrap_or(0));
    jobs
}

/// Renders one scene's noisy images and reference into its folder; returns its record
/// (the caller writes it as `done.json`).
fn render_scene(
    opts: &Options,
    out: &Path,
    Job {
        name,
        split,
        text,
        sampling,
        family,
        ..
    }: &Job,
    progress: &(dyn Fn(usize) + Sync),
    cancel: &AtomicBool,
) -> Result<Record, String> {
    let dir: PathBuf = out.join(split).join(name);
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    write_bytes_atomic(&dir.join("scene.txt"), text.as_bytes())?;
    let sc = format::parse(text, name, None)?;
    let base = Settings {
        width: opts.size,
        height: opts.size,
        spp: 1,
        // Seeded by the scene's name, so the order of work does not matter.
        seed: opts.seed ^ fnv1a(name.as_bytes()),
        max_depth: 12,
        kernel: None,
        sampling: *sampling,
    };
    let t0 = Instant::now();
    let noisy = render_progressive(&sc, &base, &opts.spp, progress, cancel)
        .map_err(|_| "cancelled".to_string())?;
    let seconds_noisy = t0.elapsed().as_secs_f64();
    let mut sorted = opts.spp.clone();
    sorted.sort_unstable();
    sorted.dedup();
    let mut files = Vec::new();
    for (spp, img) in sorted.iter().zip(&noisy) {
        let f = format!("spp{spp:04}.exr");
        img.write_exr(&dir.join(&f))?;
        files.push((*spp, f));
    }
    let t1 = Instant::now();
    let ref_checkpoints = reference_checkpoints(opts);
    let reference = render_progressive(
        &sc,
        &Settings {
            seed: !base.seed,
            sampling: Sampling::DEFAULT,
            ..base
        },
        &ref_checkpoints,
        progress,
        cancel,
    )
    .map_err(|_| "cancelled".to_string())?;
    let seconds_reference = t1.elapsed().as_secs_f64();
    let mut reference_prefixes = Vec::new();
    for (spp, img) in ref_checkpoints.iter().zip(&reference) {
        let f = if *spp == opts.ref_spp {
            "ref.exr".to_string()
        } else {
            reference_prefixes.push((*spp, format!("ref-spp{spp:04}.exr")));
            format!("ref-spp{spp:04}.exr")
        };
        img.write_exr(&dir.join(&f))?;
    }
    Ok(Record {
        name: name.clone(),
        split: split.to_string(),
        dir: format!("{split}/{name}"),
        noisy: files,
        reference: "ref.exr".into(),
        reference_prefixes,
        seconds_noisy,
        seconds_reference,
        features: format!("{:?}", sc.features()),
        sampling: sampling.to_string(),
        family: family.to_string(),
    })
}

/// The reference render's checkpoints: the prefixes below `ref_spp`, then `ref_spp`
/// (sorted, deduplicated, so the last is the full reference).
fn reference_checkpoints(opts: &Options) -> Vec<u32> {
    let mut cps: Vec<u32> = opts
        .ref_prefix_spp
        .iter()
        .copied()
        .filter(|&c| c > 0 && c < opts.ref_spp)
        .chain([opts.ref_spp])
        .collect();
    cps.sort_unstable();
    cps.dedup();
    cps
}

/// FNV-1a, a stable hash for seeds.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

/// Writes the manifest of `records`: `manifest.json`, or for a part its own file.
fn write_manifest(
    opts: &Options,
    out: &Path,
    part: Option<Part>,
    records: &[Record],
) -> Result<Manifest, String> {
    let part_of = part.map(|p| PartOf {
        index: p.index,
        count: p.count,
        // As `jobs` takes it, so equal orders compare equal.
        start: opts.start.checked_rem(opts.count).unwrap_or(0),
    });
    let m = Manifest::new(opts, records.to_vec(), part_of);
    m.write(
        out,
        &part.map_or("manifest.json".into(), |p| p.manifest_name()),
    )?;
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Settings of a data set of `count` 8x8 scenes at 1 spp, no named scenes.
    fn tiny(count: usize, holdout: usize, start: usize) -> Options {
        Options {
            count,
            size: 8,
            spp: vec![1],
            ref_spp: 2,
            seed: 3,
            named: false,
            holdout,
            ref_prefix_spp: vec![],
            start,
            weak_share: 0.0,
            families: Families::V2,
            only_split: None,
        }
    }

    #[test]
    fn start_rotates_the_order_not_the_set() {
        let opts = |start| tiny(7, 0, start);
        let (a, b) = (jobs(&opts(0)), jobs(&opts(12)));
        assert_eq!(b[0].name, "scene-00005");
        assert_eq!(b[2].name, "scene-00000");
        let mut sorted = b.clone();
        sorted.sort_by_key(|j| j.index);
        assert_eq!(sorted, a);
    }

    #[test]
    fn parts_split_the_set_evenly_and_keep_its_order() {
        let opts = Options {
            named: true,
            ..tiny(11, 2, 4)
        };
        let all = jobs(&opts);
        let n = 3;
        let parts: Vec<Vec<Job>> = (1..=n)
            .map(|i| {
                let p = Part::new(i, n).unwrap();
                all.iter()
                    .filter(|j| p.contains(j.index))
                    .cloned()
                    .collect()
            })
            .collect();
        let sizes: Vec<usize> = parts.iter().map(Vec::len).collect();
        assert!(
            sizes.iter().max().unwrap() - sizes.iter().min().unwrap() <= 1,
            "{sizes:?}"
        );
        // Every kind of scene lands in every part.
        for part in &parts {
            for kind in ["named-", "holdout-", "scene-"] {
                assert!(part.iter().any(|j| j.name.starts_with(kind)), "{kind}");
            }
        }
        let mut joined: Vec<Job> = parts.concat();
        joined.sort_by_key(|j| all.iter().position(|a| a.name == j.name));
        assert_eq!(joined, all);
    }

    #[test]
    fn a_generated_scene_keeps_its_part_when_the_set_grows() {
        let index = |count| {
            jobs(&tiny(count, 2, 0))
                .into_iter()
                .find(|j| j.name == "scene-00003")
                .map(|j| j.index)
        };
        assert_eq!(index(5), index(50));
    }

    #[test]
    fn a_resumed_set_lists_its_finished_scenes_before_rendering_more() {
        let out = std::env::temp_dir().join(format!("temc-dataset-resume-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        let opts = |count, start| tiny(count, 0, start);
        let (quiet, none) = (|_: &str| {}, |_: usize| {});
        run(
            &opts(2, 0),
            &out,
            None,
            &quiet,
            &none,
            &AtomicBool::new(false),
        )
        .unwrap();
        std::fs::remove_file(out.join("manifest.json")).unwrap();
        // Grown by one scene, rendered first and cancelled at once: the two finished
        // scenes must still be in the manifest (they come after the new one in order).
        let err = run(
            &opts(3, 2),
            &out,
            None,
            &quiet,
            &none,
            &AtomicBool::new(true),
        );
        assert!(err.is_err());
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap())
                .unwrap();
        let names: Vec<_> = m["scenes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["name"].as_str().unwrap().to_string())
            .collect();
        assert_eq!(names, ["scene-00000", "scene-00001"]);
        std::fs::remove_dir_all(&out).unwrap();
    }

    #[test]
    fn a_split_alone_renders_its_scenes_and_a_whole_run_adds_the_rest() {
        let out = std::env::temp_dir().join(format!("temc-dataset-split-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        let whole = tiny(20, 1, 0);
        let test_only = Options {
            only_split: Some("test".into()),
            ..whole.clone()
        };
        let (quiet, none, go) = (|_: &str| {}, |_: usize| {}, AtomicBool::new(false));
        let m = run(&test_only, &out, None, &quiet, &none, &go).unwrap();
        let want: Vec<_> = jobs(&whole)
            .into_iter()
            .filter(|j| j.split == "test")
            .map(|j| j.name)
            .collect();
        assert!(want.iter().any(|n| n.starts_with("scene-")), "{want:?}");
        let names = |m: &Manifest| m.scenes.iter().map(|r| r.name.clone()).collect::<Vec<_>>();
        assert_eq!(names(&m), want);
        // The whole set in the same folder: the test scenes are kept, not rendered again.
        let kept = std::fs::read(out.join("test").join(&want[0]).join("done.json")).unwrap();
        let m = run(&whole, &out, None, &quiet, &none, &go).unwrap();
        assert_eq!(m.scenes.len(), jobs(&whole).len());
        let again = std::fs::read(out.join("test").join(&want[0]).join("done.json")).unwrap();
        assert_eq!(kept, again);
        std::fs::remove_dir_all(&out).unwrap();
    }

    #[test]
    fn held_out_families_go_to_the_test_split_only() {
        let opts = tiny(20, 2, 0);
        let held: Vec<_> = jobs(&opts)
            .into_iter()
            .filter(|j| j.name.starts_with("holdout-"))
            .collect();
        let names: Vec<_> = held.iter().map(|j| j.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "holdout-window-000",
                "holdout-window-001",
                "holdout-corridor-000",
                "holdout-corridor-001"
            ]
        );
        assert!(held.iter().all(|j| j.split == "test"));
    }

    #[test]
    fn weak_sampling_is_a_seeded_share_of_the_generated_scenes() {
        let opts = |weak_share, seed| Options {
            weak_share,
            seed,
            ..tiny(1000, 0, 0)
        };
        let picks =
            |o: &Options| -> Vec<Sampling> { (0..o.count).map(|i| weak_sampling(o, i)).collect() };
        let weak = |v: &[Sampling]| v.iter().filter(|s| !s.is_default()).count();
        let (third, half) = (picks(&opts(0.3, 3)), picks(&opts(0.5, 3)));
        assert!((250..=350).contains(&weak(&third)), "{}", weak(&third));
        assert_eq!(third, picks(&opts(0.3, 3)), "deterministic");
        assert_ne!(third, picks(&opts(0.3, 4)), "seeded");
        assert_eq!(weak(&picks(&opts(0.0, 3))), 0);
        assert_eq!(weak(&picks(&opts(1.0, 3))), 1000);
        // A larger share keeps the scenes a smaller one made weak, with their modes.
        for (a, b) in third.iter().zip(&half) {
            assert!(a.is_default() || a == b);
        }
        // Every valid combination of the modes occurs.
        let all = picks(&opts(1.0, 3));
        for c in Sampling::weak_combinations() {
            assert!(all.contains(&c), "{c} never picked");
        }
        // Only generated scenes are weakened.
        let named = Options {
            named: true,
            ..opts(1.0, 3)
        };
        for j in jobs(&Options { count: 4, ..named }) {
            assert_eq!(
                j.sampling.is_default(),
                !j.name.starts_with("scene-"),
                "{}",
                j.name
            );
        }
    }

    #[test]
    fn weak_scenes_are_recorded_and_counted_and_their_share_is_a_setting() {
        let out = std::env::temp_dir().join(format!("temc-dataset-weak-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        let opts = Options {
            weak_share: 0.5,
            ..tiny(6, 0, 0)
        };
        let (quiet, none, go) = (|_: &str| {}, |_: usize| {}, AtomicBool::new(false));
        let m = run(&opts, &out, None, &quiet, &none, &go).unwrap();
        let mut counts = BTreeMap::new();
        for (job, r) in jobs(&opts).iter().zip(&m.scenes) {
            assert_eq!(r.sampling, job.sampling.to_string(), "{}", r.name);
            *counts.entry(r.sampling.clone()).or_insert(0) += 1;
        }
        assert!(m.scenes.iter().any(|r| r.sampling != "default"));
        assert_eq!(m.sampling, counts);
        let settings = std::fs::read_to_string(out.join("dataset.json")).unwrap();
        assert!(settings.contains("\"weak_share\": 0.5"), "{settings}");
        // Another share in the same folder is refused.
        let other = Options {
            weak_share: 0.0,
            ..opts.clone()
        };
        let err = run(&other, &out, None, &quiet, &none, &go).unwrap_err();
        assert!(err.contains("other settings"), "{err}");
        std::fs::remove_dir_all(&out).unwrap();
        // A set without weak scenes writes its settings as before the option.
        let plain = serde_json::to_string(&tiny(6, 0, 0)).unwrap();
        assert!(!plain.contains("weak_share"), "{plain}");
        let read: Options = serde_json::from_str(&plain).unwrap();
        assert_eq!(read.weak_share, 0.0);
    }

    #[test]
    fn v2_families_keep_the_generator_and_all_draws_from_every_family() {
        let v2 = jobs(&tiny(40, 1, 0));
        for j in v2.iter().filter(|j| j.name.starts_with("scene-")) {
            let i: u64 = j.name[6..].parse().unwrap();
            let text = temc_render::description::generate::scene_text(3 * 1_000_003 + i);
            assert_eq!(j.text, text, "{}", j.name);
            assert!(["room", "open"].contains(&j.family), "{}", j.family);
        }
        let all = jobs(&Options {
            families: Families::All,
            ..tiny(40, 1, 0)
        });
        let kinds: std::collections::BTreeSet<_> = all.iter().map(|j| j.family).collect();
        for f in families::FAMILIES.iter().chain(&held_out::FAMILIES) {
            assert!(kinds.contains(f), "{f} never drawn: {kinds:?}");
        }
        // Only the generated scenes change; a room or open floor drawn by both is the same.
        for (a, b) in v2.iter().zip(&all) {
            if !a.name.starts_with("scene-") || a.family == b.family {
                assert_eq!(a, b);
            }
        }
    }

    #[test]
    fn families_are_recorded_and_counted_and_are_a_setting() {
        let out = std::env::temp_dir().join(format!("temc-dataset-fam-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out);
        let opts = Options {
            families: Families::All,
            ..tiny(6, 0, 0)
        };
        let (quiet, none, go) = (|_: &str| {}, |_: usize| {}, AtomicBool::new(false));
        let m = run(&opts, &out, None, &quiet, &none, &go).unwrap();
        let mut counts = BTreeMap::new();
        for (job, r) in jobs(&opts).iter().zip(&m.scenes) {
            assert_eq!(r.family, job.family, "{}", r.name);
            *counts.entry(r.family.clone()).or_insert(0) += 1;
        }
        assert_eq!(m.families, counts);
        let settings = std::fs::read_to_string(out.join("dataset.json")).unwrap();
        assert!(settings.contains("\"families\": \"all\""), "{settings}");
        let other = Options {
            families: Families::V2,
            ..opts.clone()
        };
        let err = run(&other, &out, None, &quiet, &none, &go).unwrap_err();
        assert!(err.contains("other settings"), "{err}");
        std::fs::remove_dir_all(&out).unwrap();
        // A v2 set writes its settings as before the option, and old settings read as v2.
        let plain = serde_json::to_string(&tiny(6, 0, 0)).unwrap();
        assert!(!plain.contains("families"), "{plain}");
        let read: Options = serde_json::from_str(&plain).unwrap();
        assert_eq!(read.families, Families::V2);
    }

    #[test]
    fn splits_are_roughly_80_10_10() {
        let mut n = std::collections::HashMap::new();
        for i in 0..1000 {
            *n.entry(split_of(i)).or_insert(0) += 1;
        }
        for (s, lo, hi) in [("train", 740, 860), ("val", 60, 140), ("test", 60, 140)] {
            assert!((lo..=hi).contains(&n[s]), "{s}: {}", n[s]);
        }
    }
}
