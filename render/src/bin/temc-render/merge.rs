//! `temc-render merge-manifests`: joins the manifests of a data set's parts
//! (`dataset --part I/N`, one `manifest.part-I-of-N.json` each) into the `manifest.json`
//! that training reads, listing the scenes in the order a whole run with the same options
//! writes them. It refuses parts rendered with different options, and names the parts
//! that are missing or unfinished.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use crate::dataset::{jobs, Manifest, Options, Record};
use crate::part::Part;

/// `temc-render merge-manifests`' options.
#[derive(clap::Args)]
pub struct Args {
    /// The data set folder the parts rendered into (their --out).
    #[arg(long)]
    out: PathBuf,
    /// How many parts the set was split into (default: the N of the folder's
    /// `manifest.part-I-of-N.json` files, if they agree).
    #[arg(long, value_name = "N")]
    parts: Option<usize>,
}

/// Merges and prints what it wrote.
pub fn main(a: Args) -> Result<(), String> {
    let m = merge(&a.out, a.parts)?;
    eprintln!(
        "temc-render: {} scenes -> {}",
        m.scenes.len(),
        a.out.join("manifest.json").display()
    );
    Ok(())
}

/// Merges the `parts` part manifests in `out` (all of them, finished) into
/// `out/manifest.json`; returns it.
pub fn merge(out: &Path, parts: Option<usize>) -> Result<Manifest, String> {
    let count = match parts {
        Some(0) => return Err("--parts must be at least 1".into()),
        Some(n) => n,
        None => part_count(out)?,
    };
    let manifests = read_parts(out, count)?;
    let opts = same_options(&manifests)?;
    // The parts' layers, not this binary's: they describe the files the parts wrote.
    let layers = manifests[0].1.layers.clone();
    let records = in_order(&opts, manifests)?;
    let m = Manifest {
        layers,
        ..Manifest::new(&opts, records, None)
    };
    m.write(out, "manifest.json")?;
    Ok(m)
}

/// The N of the part manifests in `out`, which must all have the same.
fn part_count(out: &Path) -> Result<usize, String> {
    let entries = std::fs::read_dir(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let mut counts: Vec<usize> = entries
        .filter_map(|e| part_of_file_name(&e.ok()?.file_name().to_string_lossy()))
        .map(|p| p.count)
        .collect();
    counts.sort_unstable();
    counts.dedup();
    match counts[..] {
        [n] => Ok(n),
        [] => Err(format!(
            "no part manifests (manifest.part-I-of-N.json) in {}: render the parts first \
             (temc-render dataset --part I/N --out {0})",
            out.display()
        )),
        _ => Err(format!(
            "{} holds part manifests of several partitions (N = {counts:?}): pass --parts N",
            out.display()
        )),
    }
}

/// The part a file name `manifest.part-I-of-N.json` names, if it is one.
fn part_of_file_name(name: &str) -> Option<Part> {
    let (i, n) = name
        .strip_prefix("manifest.part-")?
        .strip_suffix(".json")?
        .split_once("-of-")?;
    Part::new(i.parse().ok()?, n.parse().ok()?).ok()
}

/// Reads parts 1..=count, or names every missing one.
fn read_parts(out: &Path, count: usize) -> Result<Vec<(Part, Manifest)>, String> {
    let parts: Vec<Part> = (1..=count)
        .map(|i| Part::new(i, count).expect("in range"))
        .collect();
    let missing: Vec<String> = parts
        .iter()
        .filter(|p| !out.join(p.manifest_name()).exists())
        .map(|p| p.to_string())
        .collect();
    if !missing.is_empty() {
        return Err(format!(
            "{} of {count} parts have no manifest in {}: part {}; render them \
             (temc-render dataset --part I/N with the same options and --out)",
            missing.len(),
            out.display(),
            missing.join(", ")
        ));
    }
    parts.into_iter().map(|p| read_part(out, p)).collect()
}

/// Reads part `p`'s manifest and checks that it says it is that part.
fn read_part(out: &Path, p: Part) -> Result<(Part, Manifest), String> {
    let path = out.join(p.manifest_name());
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let m: Manifest =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    match m.part {
        Some(of) if (of.index, of.count) == (p.index, p.count) => Ok((p, m)),
        _ => Err(format!(
            "{}: not the manifest of part {p} (it says {:?})",
            path.display(),
            m.part
        )),
    }
}

/// The options every part was rendered with (with their `--start`), or which part differs.
fn same_options(manifests: &[(Part, Manifest)]) -> Result<Options, String> {
    let (first, m0) = &manifests[0];
    let start0 = m0.part.expect("checked by read_part").start;
    for (p, m) in &manifests[1..] {
        if m.options != m0.options || m.layers != m0.layers {
            return Err(format!(
                "part {p} was rendered with other options than part {first}: {:?} against \
                 {:?}; render every part with the same options",
                m.options, m0.options
            ));
        }
        let start = m.part.expect("checked by read_part").start;
        if start != start0 {
            return Err(format!(
                "part {p} was rendered with --start {start} and part {first} with --start \
                 {start0}, so the merged order is ambiguous; rerun part {p} with --start \
                 {start0} (it renders nothing again, it only rewrites its manifest)"
            ));
        }
    }
    Ok(Options {
        start: start0,
        ..m0.options.clone()
    })
}

/// The parts' records in the order a whole run of `opts` lists them, or which part has
/// not finished which scenes.
fn in_order(opts: &Options, manifests: Vec<(Part, Manifest)>) -> Result<Vec<Record>, String> {
    let count = manifests.len();
    let mut by_name: HashMap<String, Record> = manifests
        .into_iter()
        .flat_map(|(_, m)| m.scenes)
        .map(|r| (r.name.clone(), r))
        .collect();
    let mut records = Vec::new();
    // Unfinished scenes by part index, so the message lists the parts in order.
    let mut unfinished: BTreeMap<usize, Vec<String>> = BTreeMap::new();
    for job in jobs(opts) {
        match by_name.remove(&job.name) {
            Some(r) if r.split != job.split => {
                return Err(format!(
                    "scene {} is in split {}, not {}",
                    r.name, r.split, job.split
                ))
            }
            Some(r) if r.sampling != job.sampling.to_string() => {
                return Err(format!(
                    "scene {} was rendered with sampling {}, not {}",
                    r.name, r.sampling, job.sampling
                ))
            }
            // Records from before the families have none.
            Some(r) if !r.family.is_empty() && r.family != job.family => {
                return Err(format!(
                    "scene {} is of family {}, not {}",
                    r.name, r.family, job.family
                ))
            }
            Some(r) => records.push(r),
            None => {
                let part = Part::holding(job.index, count);
                unfinished.entry(part.index).or_default().push(job.name);
            }
        }
    }
    if !unfinished.is_empty() {
        return Err(unfinished_message(count, &unfinished));
    }
    if let Some(name) = by_name.keys().next() {
        return Err(format!(
            "the parts list {name}, which is not in the set of {opts:?}"
        ));
    }
    Ok(records)
}

/// Names the unfinished parts and their first few missing scenes.
fn unfinished_message(count: usize, unfinished: &BTreeMap<usize, Vec<String>>) -> String {
    let parts: Vec<String> = unfinished
        .iter()
        .map(|(i, names)| {
            let more = if names.len() > 3 { ", ..." } else { "" };
            let first: Vec<&str> = names.iter().take(3).map(String::as_str).collect();
            format!(
                "part {i}/{count} lacks {} scene(s) ({}{more})",
                names.len(),
                first.join(", ")
            )
        })
        .collect();
    format!(
        "not every part has finished: {}; rerun those parts to resume them",
        parts.join("; ")
    )
}
