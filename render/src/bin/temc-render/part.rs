//! `--part I/N`: which scenes of a data set one process of a cluster renders.
//!
//! The data set's scenes have a fixed global order (`dataset::jobs` at `--start 0`: named
//! scenes, held-out families, generated scenes). Part I of N (1-based, as Slurm's
//! `--array=1-N` numbers its tasks) renders the scenes whose global index `k` has
//! `k % N == I - 1`. Striding rather than contiguous blocks, because the list is sorted by
//! kind and the kinds cost differently (the named stress scenes and held-out rooms come
//! first): striding gives every part the same mix, so the parts finish together and
//! their scene counts differ by at most one. A generated scene's index does not depend on
//! `--count`, so a grown set keeps each earlier scene in its part.

use std::fmt;
use std::str::FromStr;

/// Part `index` (1-based) of `count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Part {
    /// Which part, 1..=count.
    pub index: usize,
    /// How many parts the set is split into.
    pub count: usize,
}

impl Part {
    /// Part `index` of `count`, or why there is no such part.
    pub fn new(index: usize, count: usize) -> Result<Part, String> {
        if count == 0 {
            return Err("the number of parts N must be at least 1".into());
        }
        if !(1..=count).contains(&index) {
            return Err(format!(
                "part {index} of {count}: parts are numbered 1 to {count} (1-based)"
            ));
        }
        Ok(Part { index, count })
    }

    /// The part of `count` that holds the scene at global index `k`.
    pub fn holding(k: usize, count: usize) -> Part {
        Part {
            index: k % count + 1,
            count,
        }
    }

    /// Whether the scene at global index `k` belongs to this part.
    pub fn contains(&self, k: usize) -> bool {
        Part::holding(k, self.count) == *self
    }

    /// The part's manifest, beside the data set's `manifest.json`: each part has its own,
    /// so parts sharing one folder never write the same file.
    pub fn manifest_name(&self) -> String {
        format!("manifest.part-{}-of-{}.json", self.index, self.count)
    }
}

impl fmt::Display for Part {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Part {
    type Err = String;

    /// Parses `I/N`; the messages name what is wrong, for clap to print.
    fn from_str(s: &str) -> Result<Part, String> {
        let (i, n) = s
            .split_once('/')
            .and_then(|(i, n)| Some((i.trim().parse().ok()?, n.trim().parse().ok()?)))
            .ok_or_else(|| {
                format!("expected I/N, part I (1-based) of N parts, e.g. 2/8; got {s:?}")
            })?;
        Part::new(i, n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_one_based_parts() {
        assert_eq!("2/8".parse(), Ok(Part { index: 2, count: 8 }));
        assert_eq!("1/1".parse(), Ok(Part { index: 1, count: 1 }));
        assert_eq!(Part::new(8, 8).unwrap().to_string(), "8/8");
    }

    #[test]
    fn refuses_parts_out_of_range_and_malformed_text() {
        for (text, says) in [
            ("0/4", "numbered 1 to 4"),
            ("5/4", "numbered 1 to 4"),
            ("1/0", "at least 1"),
            ("0/0", "at least 1"),
            ("2", "expected I/N"),
            ("a/4", "expected I/N"),
            ("-1/4", "expected I/N"),
            ("1/4/2", "expected I/N"),
            ("1/99999999999999999999999", "expected I/N"),
            ("", "expected I/N"),
        ] {
            let e = text.parse::<Part>().unwrap_err();
            assert!(e.contains(says), "{text}: {e}");
        }
    }

    #[test]
    fn parts_cover_every_index_once() {
        for n in 1..6 {
            for k in 0..40 {
                let owners: Vec<_> = (1..=n)
                    .map(|i| Part::new(i, n).unwrap())
                    .filter(|p| p.contains(k))
                    .collect();
                assert_eq!(owners, [Part::holding(k, n)], "index {k} of {n} parts");
            }
        }
    }
}
