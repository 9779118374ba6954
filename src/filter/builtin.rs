//! The models built into the library: TEMC-2 fast, balanced and high, embedded from onnx/
//! at compile time (their model cards sit beside them there). Balanced is a network of
//! 3 pyramid levels, which reach farther and cut the noise one 5x5 level leaves, with its
//! coarse levels capped and composed bilinearly (docs/reconstruction.md, "High: three
//! levels, fenced"); high is the same network with `temc.passes` 2, run on each tile and
//! its half turn and averaged (docs/reconstruction.md, "A flip ensemble"). Fast is one
//! level at half the width. The baselines (TEMC-1, DEMC, AE) ship as files in
//! onnx/baselines/ and need "weights".

use std::sync::{Arc, OnceLock};

use super::Quality;

const FAST: &[u8] = include_bytes!("../../onnx/temc2-fast.onnx");
const BALANCED: &[u8] = include_bytes!("../../onnx/temc2-balanced.onnx");
const HIGH: &[u8] = include_bytes!("../../onnx/temc2-high.onnx");

/// The built-in ONNX model for filter type `kind` at `quality`, if this build has one
/// (only "TEMC2" does). `quality` is resolved first ([`Quality::resolve`]:
/// [`Quality::Default`] is [`Quality::Balanced`]).
///
/// ```
/// use temc::filter::{builtin_model, Quality};
/// let onnx = builtin_model("TEMC2", Quality::Default).unwrap();
/// let info = temc::engine::Model::from_bytes(onnx).unwrap().info().clone();
/// assert_eq!(info.architecture, "temc2");
/// assert!(builtin_model("DEMC", Quality::High).is_none());
/// ```
pub fn builtin_model(kind: &str, quality: Quality) -> Option<&'static [u8]> {
    (kind == "TEMC2").then_some(match quality.resolve() {
        Quality::Fast => FAST,
        Quality::Default | Quality::Balanced => BALANCED,
        Quality::High => HIGH,
    })
}

/// [`builtin_model`] as shared bytes, one allocation per model for the whole process, so
/// that filters recommitted with the same quality reuse their loaded model.
pub(super) fn shared(kind: &str, quality: Quality) -> Option<Arc<[u8]>> {
    static CACHE: [OnceLock<Arc<[u8]>>; 3] = [const { OnceLock::new() }; 3];
    let bytes = builtin_model(kind, quality)?;
    // One slot per distinct model.
    let slot = match quality.resolve() {
        Quality::Fast => 0,
        Quality::Default | Quality::Balanced => 1,
        Quality::High => 2,
    };
    Some(CACHE[slot].get_or_init(|| Arc::from(bytes)).clone())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::Model;

    /// Each quality mode is a trained TEMC-2 that reconstructs at several pyramid levels
    /// (issue 36: several scales); fast is a narrower network than balanced, and high runs
    /// balanced's network over more flip passes.
    #[test]
    fn quality_modes_are_trained_temc2_of_growing_cost() {
        let shape = |q| {
            let info = Model::from_bytes(builtin_model("TEMC2", q).unwrap())
                .unwrap()
                .info()
                .clone();
            assert_eq!(info.architecture, "temc2");
            assert!(
                !info.is_untrained(),
                "{q:?}: the built-in model is untrained"
            );
            (info.width, info.levels, info.passes)
        };
        let (fast, balanced, high) = (
            shape(Quality::Fast),
            shape(Quality::Balanced),
            shape(Quality::High),
        );
        assert!(fast.0 < balanced.0, "{fast:?} {balanced:?}");
        assert!(fast.1 >= 3 && fast.2 == 1, "{fast:?}");
        assert!(balanced.1 >= 3 && balanced.2 == 1, "{balanced:?}");
        assert!(
            high.0 == balanced.0 && high.1 == balanced.1,
            "{balanced:?} {high:?}"
        );
        assert!(high.2 > balanced.2, "{balanced:?} {high:?}");
        // Not assert_eq: a failure would print megabytes of model.
        assert!(
            builtin_model("TEMC2", Quality::Default) == builtin_model("TEMC2", Quality::Balanced)
        );
        assert!(builtin_model("TEMC2", Quality::High) != builtin_model("TEMC2", Quality::Balanced));
        for kind in ["TEMC1", "DEMC", "AE"] {
            assert!(builtin_model(kind, Quality::Balanced).is_none());
        }
    }

    #[test]
    fn shared_bytes_are_allocated_once() {
        let a = shared("TEMC2", Quality::High).unwrap();
        let b = shared("TEMC2", Quality::High).unwrap();
        assert!(Arc::ptr_eq(&a, &b));
        // Default shares balanced's slot; each model has its own.
        let c = shared("TEMC2", Quality::Balanced).unwrap();
        assert!(Arc::ptr_eq(&c, &shared("TEMC2", Quality::Default).unwrap()));
        assert!(!Arc::ptr_eq(&a, &c));
        assert!(!Arc::ptr_eq(&a, &shared("TEMC2", Quality::Fast).unwrap()));
        assert!(shared("AE", Quality::High).is_none());
    }
}
