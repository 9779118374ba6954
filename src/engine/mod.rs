//! Runs a temc ONNX model with tract, one cached fixed-size plan per tile shape.
//!
//! tract plans built for symbolic H x W either fail to load or run several times slower
//! (no direct convolution without concrete shapes, see docs/tract-vs-onnxruntime.md), while
//! a concrete plan builds in milliseconds to a few hundred. So a [`Model`] keeps the parsed
//! graph and builds one optimised plan per (H, W) on first use, keeping the most recently
//! used few ([`PLAN_CACHE_SIZES`]); plans are shared between threads (`Arc`), and each run
//! gets its own state.

mod metadata;
mod plan_cache;

pub use metadata::{ModelInfo, AUX_BUFFERS, AUX_LAYOUT, FORMAT_VERSION, PASS_COUNTS};
pub use plan_cache::PLAN_CACHE_SIZES;

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex};

use tract_onnx::prelude::*;

use crate::Error;
use plan_cache::PlanCache;

/// Names of the graph's inputs, in the order [`Model::run`] takes them.
pub const INPUT_NAMES: [&str; 3] = ["chroma", "luma", "aux"];
/// Names of the graph's outputs: `filters0` (full resolution) .. `filters{levels-1}`, one per
/// pyramid level of the reconstruction (docs/reconstruction.md).
pub fn output_name(level: usize) -> String {
    format!("filters{level}")
}

type Plan = TypedSimplePlan;

/// The network's inputs for one tile, each NCHW with N = 1, row-major.
#[derive(Clone, Copy, Debug)]
pub struct NetInput<'a> {
    /// (H, S) planes: `chroma_channels * h * w` values.
    pub chroma: &'a [f32],
    /// V plane: `h * w` values.
    pub luma: &'a [f32],
    /// Aux planes: `aux_channels * h * w` values.
    pub aux: &'a [f32],
}

/// A loaded model: its metadata, its parsed graph, and a cache of size-specific plans.
pub struct Model {
    info: ModelInfo,
    graph: InferenceModel,
    /// Position of chroma, luma and aux among the graph's inputs.
    input_order: [usize; 3],
    /// Position of level l's filters among the graph's outputs.
    output_order: Vec<usize>,
    plans: Mutex<PlanCache<Plan>>,
    memory: std::sync::OnceLock<(f64, f64)>,
}

impl std::fmt::Debug for Model {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Model")
            .field("info", &self.info)
            .finish_non_exhaustive()
    }
}

fn model_err(context: &str) -> impl Fn(TractError) -> Error + '_ {
    move |e| Error::Model(format!("{context}: {e:#}"))
}

/// Refuses what tract 0.23.9 would panic on instead of reporting (the `weights` fuzz
/// target, 2026-12-02): a graph output that no input, initializer or node names (tract
/// indexes its name map with it). Control-flow subgraphs, which temc's feed-forward models
/// never hold, are refused too: their names are resolved the same way.
fn check_graph(proto: &tract_onnx::pb::ModelProto) -> Result<(), Error> {
    let Some(g) = &proto.graph else {
        return Ok(()); // tract reports a missing graph as an error itself
    };
    let subgraphs = |n: &tract_onnx::pb::NodeProto| {
        n.attribute
            .iter()
            .any(|a| a.g.is_some() || !a.graphs.is_empty())
    };
    if let Some(n) = g.node.iter().find(|n| subgraphs(n)) {
        return Err(Error::Model(format!(
            "node {:?} ({}): control-flow subgraphs are not supported",
            n.name, n.op_type
        )));
    }
    let named: std::collections::HashSet<&str> = g
        .input
        .iter()
        .map(|i| i.name.as_str())
        .chain(g.initializer.iter().map(|t| t.name.as_str()))
        .chain(
            g.node
                .iter()
                .flat_map(|n| n.input.iter().chain(&n.output))
                .map(String::as_str),
        )
        .filter(|s| !s.is_empty())
        .collect();
    match g.output.iter().find(|o| !named.contains(o.name.as_str())) {
        Some(o) => Err(Error::Model(format!(
            "graph output {:?} is not produced by the graph",
            o.name
        ))),
        None => Ok(()),
    }
}

impl Model {
    /// Loads a model from the bytes of an ONNX file (e.g. one embedded in the library or
    /// handed over through the C ABI). The file must carry temc metadata.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, Error> {
        let onnx = tract_onnx::onnx();
        let proto = onnx
            .proto_model_for_read(&mut &bytes[..])
            .map_err(model_err("not a readable ONNX model"))?;
        check_graph(&proto)?;
        let info = ModelInfo::from_props(
            proto
                .metadata_props
                .iter()
                .map(|e| (e.key.as_str(), e.value.as_str())),
        )?;
        let graph = onnx
            .model_for_proto_model(&proto)
            .map_err(model_err("ONNX graph not supported"))?;
        Self::new(info, graph)
    }

    /// Loads a model from an ONNX file.
    pub fn from_path(path: impl AsRef<Path>) -> Result<Self, Error> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_bytes(&bytes)
    }

    fn new(info: ModelInfo, graph: InferenceModel) -> Result<Self, Error> {
        let names: Vec<String> = graph
            .input_outlets()
            .map_err(model_err("graph inputs"))?
            .iter()
            .map(|o| graph.node(o.node).name.clone())
            .collect();
        let mut input_order = [0; 3];
        for (slot, want) in input_order.iter_mut().zip(INPUT_NAMES) {
            *slot = names.iter().position(|n| n == want).ok_or_else(|| {
                Error::Model(format!(
                    "the graph has no input named {want:?} (inputs: {names:?})"
                ))
            })?;
        }
        if names.len() != 3 {
            return Err(Error::Model(format!(
                "expected exactly the inputs {INPUT_NAMES:?}, found {names:?}"
            )));
        }
        let outputs = graph.output_outlets().map_err(model_err("graph outputs"))?;
        // An output is named by its outlet label (the ONNX value name), not its node.
        let out_names: Vec<String> = outputs
            .iter()
            .map(|o| {
                graph
                    .outlet_label(*o)
                    .unwrap_or(&graph.node(o.node).name)
                    .to_string()
            })
            .collect();
        let want: Vec<String> = (0..info.levels).map(output_name).collect();
        let output_order = want
            .iter()
            .map(|n| out_names.iter().position(|o| o == n))
            .collect::<Option<Vec<usize>>>()
            .filter(|_| out_names.len() == want.len())
            .ok_or_else(|| {
                Error::Model(format!(
                    "expected the outputs {want:?} (temc.levels = {}), found {out_names:?}",
                    info.levels
                ))
            })?;
        Ok(Self {
            info,
            graph,
            input_order,
            output_order,
            plans: Mutex::new(PlanCache::new()),
            memory: std::sync::OnceLock::new(),
        })
    }

    /// The model's metadata.
    pub fn info(&self) -> &ModelInfo {
        &self.info
    }

    /// Checks that an H x W run is allowed: non-zero multiples of the alignment.
    pub fn check_size(&self, h: usize, w: usize) -> Result<(), Error> {
        let a = self.info.alignment;
        if h == 0 || w == 0 || !h.is_multiple_of(a) || !w.is_multiple_of(a) {
            return Err(Error::InvalidArgument(format!(
                "tile {h}x{w} is not a non-zero multiple of the model's alignment {a}"
            )));
        }
        Ok(())
    }

    /// The optimised plan for H x W, built on first use and cached (the least recently used
    /// of more than [`PLAN_CACHE_SIZES`] sizes is dropped).
    pub fn plan(&self, h: usize, w: usize) -> Result<Arc<Plan>, Error> {
        self.check_size(h, w)?;
        if let Some(p) = self.cache().get((h, w)) {
            return Ok(p);
        }
        // Built outside the lock: other sizes must not wait for this one. Two threads that
        // race on the same new size both build it; the second insert wins, both are valid.
        let plan = Arc::new(self.build_plan(h, w)?);
        self.cache().insert((h, w), plan.clone());
        Ok(plan)
    }

    fn cache(&self) -> std::sync::MutexGuard<'_, PlanCache<Plan>> {
        // Every update is one map operation, so a poisoned lock is still consistent.
        self.plans.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The memory one run needs, as `(weight bytes, activation bytes per pixel)`: weights
    /// are shared by every run of the model; activations are the peak of tensors alive at
    /// once when the plan's nodes run in order and each output is freed after its last
    /// consumer (tract's own policy), measured at two tile sizes. Computed once.
    pub fn memory_estimate(&self) -> Result<(f64, f64), Error> {
        if let Some(e) = self.memory.get() {
            return Ok(*e);
        }
        let a = self.info.alignment;
        let (s1, s2) = (2 * a, 4 * a);
        // The two plans take about 0.06 s each to build: side by side on a rayon pool's
        // threads when called from one, else in turn (no threads of the library's own).
        let (first, second) = if rayon::current_thread_index().is_some() {
            rayon::join(|| self.plan_bytes(s1), || self.plan_bytes(s2))
        } else {
            (self.plan_bytes(s1), self.plan_bytes(s2))
        };
        let ((weights, p1), (_, p2)) = (first?, second?);
        let per_px = ((p2 - p1) / ((s2 * s2 - s1 * s1) as f64)).max(p2 / (s2 * s2) as f64);
        Ok(*self.memory.get_or_init(|| (weights, per_px)))
    }

    /// (constant bytes, peak live activation bytes) of the plan for an s x s tile.
    fn plan_bytes(&self, s: usize) -> Result<(f64, f64), Error> {
        // A plan built only for measuring is not kept: it would push out one in use.
        let cached = self.cache().get((s, s));
        let plan = match cached {
            Some(p) => p,
            None => Arc::new(self.build_plan(s, s)?),
        };
        let model = plan.model();
        let bytes = |n: usize| -> f64 {
            model
                .node(n)
                .outputs
                .iter()
                .map(|o| {
                    o.fact
                        .shape
                        .as_concrete()
                        .map_or(0.0, |sh| sh.iter().product::<usize>() as f64)
                        * o.fact.datum_type.size_of() as f64
                })
                .sum()
        };
        let order = plan.order_without_consts();
        let step: HashMap<usize, usize> = order.iter().enumerate().map(|(i, &n)| (n, i)).collect();
        let outputs: Vec<usize> = model
            .output_outlets()
            .map_err(model_err("outputs"))?
            .iter()
            .map(|o| o.node)
            .collect();
        // Last step at which each node's outputs are read.
        let mut last_use = vec![0usize; model.nodes().len()];
        for (i, &n) in order.iter().enumerate() {
            for input in &model.node(n).inputs {
                last_use[input.node] = last_use[input.node].max(i);
            }
        }
        let consts: f64 = (0..model.nodes().len())
            .filter(|n| !step.contains_key(n))
            .map(bytes)
            .sum();
        let (mut live, mut peak) = (0.0f64, 0.0f64);
        let mut freed_at: Vec<Vec<usize>> = vec![Vec::new(); order.len()];
        for &n in order {
            if !outputs.contains(&n) && last_use[n] >= step[&n] {
                freed_at[last_use[n]].push(n);
            }
        }
        for (i, &n) in order.iter().enumerate() {
            live += bytes(n);
            peak = peak.max(live);
            for &f in &freed_at[i] {
                live -= bytes(f);
            }
        }
        Ok((consts, peak))
    }

    /// The sizes whose plans are cached: at most [`PLAN_CACHE_SIZES`], the most recently
    /// used.
    pub fn cached_sizes(&self) -> Vec<(usize, usize)> {
        self.cache().sizes()
    }

    fn build_plan(&self, h: usize, w: usize) -> Result<Plan, Error> {
        let channels = [self.info.chroma_channels, 1, self.info.aux_channels];
        let mut g = self.graph.clone();
        for (k, &slot) in self.input_order.iter().enumerate() {
            g = g
                .with_input_fact(slot, f32::fact([1, channels[k], h, w]).into())
                .map_err(model_err("setting input shapes"))?;
        }
        let ctx = format!("planning {h}x{w}");
        g.into_optimized()
            .and_then(|m| m.into_runnable())
            .map_err(|e| Error::Model(format!("{ctx}: {e:#}")))
            .and_then(|p| {
                Arc::try_unwrap(p).map_err(|_| Error::Model(format!("{ctx}: plan shared")))
            })
    }

    /// Runs the network on one H x W tile; returns the filter logits of every level, level l
    /// holding `filter_channels x (H >> l) x (W >> l)` values ([`NetOutput::levels`]).
    pub fn run(&self, input: NetInput<'_>, h: usize, w: usize) -> Result<NetOutput, Error> {
        let plan = self.plan(h, w)?;
        let hw = h * w;
        let parts = [
            (input.chroma, self.info.chroma_channels),
            (input.luma, 1),
            (input.aux, self.info.aux_channels),
        ];
        let mut tensors: Vec<Option<TValue>> = vec![None, None, None];
        for (k, (data, c)) in parts.into_iter().enumerate() {
            if data.len() != c * hw {
                return Err(Error::InvalidArgument(format!(
                    "input {:?}: expected {c}x{h}x{w} = {} values, got {}",
                    INPUT_NAMES[k],
                    c * hw,
                    data.len()
                )));
            }
            let t = Tensor::from_shape(&[1, c, h, w], data)
                .map_err(|e| Error::Inference(format!("{e:#}")))?;
            tensors[self.input_order[k]] = Some(t.into());
        }
        let inputs: TVec<TValue> = tensors
            .into_iter()
            .map(|t| t.ok_or_else(|| Error::Model("a network input was not set".into())))
            .collect::<Result<_, _>>()?;
        let out = plan
            .run(inputs)
            .map_err(|e| Error::Inference(format!("{h}x{w}: {e:#}")))?;
        clean_vector_state();
        let output = NetOutput {
            tensors: out,
            order: self.output_order.clone(),
            channels: self.info.filter_channels(),
            size: (h, w),
        };
        output.levels()?;
        Ok(output)
    }
}

/// Marks the upper halves of the vector registers clean after tract's AVX-512 kernels,
/// which can leave them dirty: until then every SSE instruction this thread runs (the
/// reconstruction's code outside its AVX paths, libm's calls) waits on those halves, and
/// the range guide's log2 over a 1056x1088 window took 0.16 s instead of 5 ms.
fn clean_vector_state() {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX; vzeroupper only zeroes bits 128 and up of the vector
        // registers, which no Rust value lives in across this call.
        unsafe { std::arch::x86_64::_mm256_zeroupper() };
    }
}

/// The network's filter logits for one tile, left in tract's own tensors: copying them out
/// cost about a tenth of a 1080p denoise (the full-resolution level alone is 248 MB for a
/// 1056x1088 window, all fresh pages).
pub struct NetOutput {
    tensors: TVec<TValue>,
    /// Position of level l's filters among `tensors`.
    order: Vec<usize>,
    channels: usize,
    size: (usize, usize),
}

impl NetOutput {
    /// Level l's logits, `filter_channels x (H >> l) x (W >> l)` values, row-major; level 0
    /// is full resolution. Errors where an output is not plain f32 memory of that size
    /// ([`Model::run`] has checked that already).
    pub fn levels(&self) -> Result<Vec<&[f32]>, Error> {
        let (h, w) = self.size;
        let c = self.channels;
        let mut levels = Vec::with_capacity(self.order.len());
        for (l, &slot) in self.order.iter().enumerate() {
            let view = self.tensors[slot]
                .try_as_plain_ram()
                .and_then(|v| v.as_slice::<f32>())
                .map_err(|e| Error::Inference(format!("reading {}: {e:#}", output_name(l))))?;
            let want = c * (h >> l) * (w >> l);
            if view.len() != want {
                return Err(Error::Model(format!(
                    "output {} has {} values, expected {c}x{}x{}",
                    output_name(l),
                    view.len(),
                    h >> l,
                    w >> l
                )));
            }
            levels.push(view);
        }
        Ok(levels)
    }
}
