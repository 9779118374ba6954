//! The models built into the library: TEMC-2 fast and balanced, embedded from onnx/ at
//! compile time (their model cards sit beside them there). High runs the balanced network
//! until a high model beats it: the 3-level width-0.25 one trailed it and was retired
//! (training/runs/RETIRED.md; commit fc46d07 holds it). The baselines (TEMC-1, DEMC, AE)
//! ship as files in onnx/baselines/ and need "weights".

use std::sync::{Arc, OnceLock};

use super::{Kind, Quality};

const FAST: &[u8] = include_bytes!("../../onnx/temc2-fast.onnx");
const BALANCED: &[u8] = include_bytes!("../../onnx/temc2-balanced.onnx");

/// The built-in ONNX model for filter type `kind` at `quality`, if this build has one
/// (only "TEMC2" does). `quality` is resolved for "TEMC2" ([`Quality::resolve`]:
/// [`Quality::Default`] is [`Quality::Balanced`]); [`Quality::High`] runs the balanced
/// network for now (see the module docs).
///
/// ```
/// use temc::filter::{builtin_model, Quality};
/// let onnx = builtin_model("TEMC2", Quality::Default).unwrap();
/// let info = temc::engine::Model::from_bytes(onnx).unwrap().info().clone();
/// assert_eq!(info.architecture, "temc2");
/// assert!(builtin_model("DEMC", Quality::High).is_none());
/// ```
pub fn builtin_model(kind: &str, quality: Quality) -> Option<&'static [u8]> {
    (kind == "TEMC2").then_some(match quality.resolve(Kind::Temc2) {
        Quality::Fast => FAST,
        Quality::Default | Quality::Balanced | Quality::High => BALANCED,
    })
}

/// [`builtin_model`] as shared bytes, one allocation per model for the whole process, so
/// that filters recommitted with the same quality reuse their loaded model.
pub(super) fn shared(kind: &str, quality: Quality) -> Option<Arc<[u8]>> {
    static CACHE: [OnceLock<Arc<[u8]>>; 2] = [const { OnceLock::new() }; 2];
    let bytes = builtin_model(kind, quality)?;
    // One slot per distinct model: high shares balanced's while it runs those bytes.
    let slot = match quality.resolve(Kind::Temc2) {
        Quality::Fast => 0,
        Quality::Default | Quality::Balanced | Quality::High => 1,
    };
    Some(CACHE[slot].get_or_init(|| Arc::from(bytes)).clone())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::Model;

    /// Each quality mode is a trained TEMC-2, and fast is a narrower network than balanced.
    /// High is balanced's bytes until a high model beats balanced (the 3-level width-0.25
    /// one trailed it; training/runs/RETIRED.md): this changes when a high model ships.
    #[test]
    fn quality_modes_are_trained_temc2_and_high_is_balanced() {
        let width = |q| {
            let info = Model::from_bytes(builtin_model("TEMC2", q).unwrap())
                .unwrap()
                .info()
                .clone();
            assert_eq!(info.architecture, "temc2");
            assert!(
                !info.is_untrained(),
                "{q:?}: the built-in model is untrained"
            );
            info.width
        };
        let (fast, balanced) = (width(Quality::Fast), width(Quality::Balanced));
        assert!(fast < balanced, "{fast} {balanced}");
        for q in [Quality::Default, Quality::High] {
            // Not assert_eq: a failure would print megabytes of model.
            assert!(
                builtin_model("TEMC2", q) == builtin_model("TEMC2", Quality::Balanced),
                "{q:?} is not the balanced model"
            );
        }
        for kind in ["TEMC1", "DEMC", "AE"] {
            assert!(builtin_model(kind, Quality::Balanced).is_none());
        }
    }

    #[test]
    fn shared_bytes_are_allocated_once() {
        let a = shared("TEMC2", Quality::High).unwrap();
        let b = shared("TEMC2", Quality::High).unwrap();
        assert!(Arc::ptr_eq(&a, &b));
        // High shares balanced's slot while it runs balanced's bytes.
        let c = shared("TEMC2", Quality::Balanced).unwrap();
        assert!(Arc::ptr_eq(&a, &c));
        assert!(!Arc::ptr_eq(&a, &shared("TEMC2", Quality::Fast).unwrap()));
        assert!(shared("AE", Quality::High).is_none());
    }
}
