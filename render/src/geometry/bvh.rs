//! A bounding volume hierarchy over all primitives of a scene (exact SAH build of a
//! binary tree, collapsed into 4-wide nodes whose boxes are tested at once; traversal
//! visits the hit children nearest first).

use std::mem::MaybeUninit;

use crate::geometry::shape::{Aabb, Packed, Prim, PrimHit};
use crate::geometry::vec3::V3;

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: first index into `order`; interior: index of the second child (the first
    /// child follows the node).
    start: u32,
    /// Leaf: number of primitives; interior: 0.
    count: u32,
}

/// The hierarchy: the binary SAH tree collapsed into nodes of four children, whose boxes
/// are tested at once (SSE2 on x86_64, a scalar loop elsewhere). Primitive indices refer
/// to the slice it was built from.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node4>,
    /// The root: an interior node (index 0) or, for a single-leaf tree, a leaf.
    root: Child,
    order: Vec<u32>,
    /// The primitives in leaf order, in the form the intersection test wants.
    packed: Vec<Packed>,
}

/// A reference to a child: an interior node (`count == 0`, `index` into `nodes`) or a leaf
/// (`count` primitives from `index` in leaf order).
#[derive(Clone, Copy, Debug, Default)]
struct Child {
    index: u32,
    count: u32,
}

/// Four children's boxes in SoA form (`lo[axis][lane]`) and references. Unused lanes have
/// the empty box (lo = +inf, hi = -inf), which no ray meets.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct Node4 {
    lo: [[f32; 4]; 3],
    hi: [[f32; 4]; 3],
    child: [Child; 4],
}

const LEAF: usize = 2;
const STACK: usize = 256;

fn axis_of(v: V3, a: usize) -> f32 {
    [v.0, v.1, v.2][a]
}

/// A ray prepared for box tests: origin, inverse direction, and per axis whether the
/// direction is negative (the box's near plane is then its upper one).
struct Ray4 {
    o: [f32; 3],
    inv: [f32; 3],
    neg: [bool; 3],
}

impl Ray4 {
    fn new(o: V3, d: V3) -> Self {
        Ray4 {
            o: [o.0, o.1, o.2],
            inv: [1.0 / d.0, 1.0 / d.1, 1.0 / d.2],
            neg: [
                d.0.is_sign_negative(),
                d.1.is_sign_negative(),
                d.2.is_sign_negative(),
            ],
        }
    }
}

/// Which of a node's four boxes the ray meets in (t_min, t_max) (bit k for lane k), and
/// the entry distance of each. NaN (0 * inf) leaves the interval as it was, as in a scalar
/// slab test.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn hit4(n: &Node4, r: &Ray4, t_min: f32, t_max: f32) -> (u32, [f32; 4]) {
    use std::arch::x86_64::*;
    // SAFETY: SSE is part of every x86_64 target; the loads and the store touch exactly
    // the four f32 of `near`, `far` and `out` (unaligned accesses need no alignment).
    unsafe {
        let mut t0 = _mm_set1_ps(t_min);
        let mut t1 = _mm_set1_ps(t_max);
        for a in 0..3 {
            let (near, far) = if r.neg[a] {
                (&n.hi[a], &n.lo[a])
            } else {
                (&n.lo[a], &n.hi[a])
            };
            let (near, far) = (_mm_loadu_ps(near.as_ptr()), _mm_loadu_ps(far.as_ptr()));
            let o = _mm_set1_ps(r.o[a]);
            let inv = _mm_set1_ps(r.inv[a]);
            let tn = _mm_mul_ps(_mm_sub_ps(near, o), inv);
            let tf = _mm_mul_ps(_mm_sub_ps(far, o), inv);
            // max/min return the second operand when either is NaN.
            t0 = _mm_max_ps(tn, t0);
            t1 = _mm_min_ps(tf, t1);
        }
        let mask = _mm_movemask_ps(_mm_cmple_ps(t0, t1)) as u32;
        let mut out = [0.0f32; 4];
        _mm_storeu_ps(out.as_mut_ptr(), t0);
        (mask, out)
    }
}

#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn hit4(n: &Node4, r: &Ray4, t_min: f32, t_max: f32) -> (u32, [f32; 4]) {
    let mut t0 = [t_min; 4];
    let mut t1 = [t_max; 4];
    for a in 0..3 {
        let (near, far) = if r.neg[a] {
            (&n.hi[a], &n.lo[a])
        } else {
            (&n.lo[a], &n.hi[a])
        };
        for k in 0..4 {
            let tn = (near[k] - r.o[a]) * r.inv[a];
            let tf = (far[k] - r.o[a]) * r.inv[a];
            if tn > t0[k] {
                t0[k] = tn;
            }
            if tf < t1[k] {
                t1[k] = tf;
            }
        }
    }
    let mut mask = 0;
    for k in 0..4 {
        if t0[k] <= t1[k] {
            mask |= 1 << k;
        }
    }
    (mask, t0)
}

/// A traversal stack entry: a child and the distance at which the ray enters its box.
#[derive(Clone, Copy)]
struct Entry {
    child: Child,
    t: f32,
}

impl Bvh {
    /// Builds over `prims`.
    pub fn build(prims: &[Prim]) -> Self {
        let bounds: Vec<Aabb> = prims.iter().map(Prim::bounds).collect();
        let centres: Vec<V3> = bounds.iter().map(Aabb::centre).collect();
        let mut order: Vec<u32> = (0..prims.len() as u32).collect();
        let mut bin = Vec::with_capacity(2 * prims.len().max(1));
        if !prims.is_empty() {
            build_node(&bounds, &centres, &mut order, 0, &mut bin);
        }
        let mut nodes = Vec::new();
        let root = if bin.is_empty() {
            Child::default()
        } else if bin[0].count > 0 {
            Child {
                index: bin[0].start,
                count: bin[0].count,
            }
        } else {
            collapse(&bin, 0, &mut nodes);
            Child { index: 0, count: 0 }
        };
        let packed = order
            .iter()
            .map(|&i| Packed::new(&prims[i as usize]))
            .collect();
        Bvh {
            nodes,
            root,
            order,
            packed,
        }
    }

    /// Nearest hit in (t_min, t_max): (primitive index, hit).
    pub fn intersect(
        &self,
        prims: &[Prim],
        o: V3,
        d: V3,
        t_min: f32,
        mut t_max: f32,
    ) -> Option<(usize, PrimHit)> {
        if self.packed.is_empty() {
            return None;
        }
        let ray = Ray4::new(o, d);
        let mut best = None;
        // Uninitialised: zeroing the whole stack would cost more than most traversals.
        let mut stack = [const { MaybeUninit::<Entry>::uninit() }; STACK];
        stack[0].write(Entry {
            child: self.root,
            t: t_min,
        });
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            // SAFETY: entries below `sp` have been written.
            let Entry { child, t } = unsafe { stack[sp].assume_init() };
            if t > t_max {
                continue; // a nearer hit was found since the box was pushed
            }
            if child.count > 0 {
                let s = child.index as usize;
                for k in s..s + child.count as usize {
                    if let Some(t) = self.packed[k].hit_t(o, d, t_min, t_max) {
                        t_max = t;
                        best = Some(self.order[k] as usize);
                    }
                }
                continue;
            }
            let node = &self.nodes[child.index as usize];
            let (mut mask, tn) = hit4(node, &ray, t_min, t_max);
            // Push the hit children farthest first, so the nearest is visited next.
            let base = sp;
            while mask != 0 {
                let k = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let e = Entry {
                    child: node.child[k],
                    t: tn[k],
                };
                let mut j = sp;
                // SAFETY: entries from `base` to `sp` have been written.
                while j > base && unsafe { stack[j - 1].assume_init() }.t < e.t {
                    stack[j] = stack[j - 1];
                    j -= 1;
                }
                stack[j].write(e);
                sp += 1;
            }
        }
        best.map(|i| (i, prims[i].surface(o + d * t_max, t_max)))
    }

    /// Whether anything blocks the segment (t_min, t_max), skipping primitive `skip`.
    pub fn occluded(&self, o: V3, d: V3, t_max: f32, skip: &[usize]) -> bool {
        if self.packed.is_empty() {
            return false;
        }
        let ray = Ray4::new(o, d);
        let mut stack = [const { MaybeUninit::<Child>::uninit() }; STACK];
        stack[0].write(self.root);
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            // SAFETY: entries below `sp` have been written.
            let child = unsafe { stack[sp].assume_init() };
            if child.count > 0 {
                let s = child.index as usize;
                for k in s..s + child.count as usize {
                    if !skip.contains(&(self.order[k] as usize))
                        && self.packed[k].hit_t(o, d, 0.0, t_max).is_some()
                    {
                        return true;
                    }
                }
                continue;
            }
            let node = &self.nodes[child.index as usize];
            let (mut mask, _) = hit4(node, &ray, 0.0, t_max);
            while mask != 0 {
                let k = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                stack[sp].write(node.child[k]);
                sp += 1;
            }
        }
        false
    }
}

/// Writes the 4-wide node for the binary interior node `b` (and, depth first, those below
/// it) into `out`; returns its index. Its children are the binary tree's nodes two levels
/// down, opening the largest interior child first until there are four.
fn collapse(bin: &[Node], b: u32, out: &mut Vec<Node4>) -> u32 {
    let mut kids: Vec<u32> = vec![b + 1, bin[b as usize].start];
    while kids.len() < 4 {
        let open = kids
            .iter()
            .enumerate()
            .filter(|(_, &k)| bin[k as usize].count == 0)
            .max_by(|x, y| {
                let ax = bin[*x.1 as usize].bounds.half_area();
                let ay = bin[*y.1 as usize].bounds.half_area();
                ax.total_cmp(&ay)
            })
            .map(|(i, _)| i);
        let Some(i) = open else { break };
        let k = kids[i];
        kids[i] = k + 1;
        kids.insert(i + 1, bin[k as usize].start);
    }
    let me = out.len() as u32;
    out.push(Node4 {
        lo: [[f32::INFINITY; 4]; 3],
        hi: [[f32::NEG_INFINITY; 4]; 3],
        child: [Child {
            index: 0,
            count: u32::MAX,
        }; 4],
    });
    for (lane, &k) in kids.iter().enumerate() {
        let n = bin[k as usize];
        let child = if n.count > 0 {
            Child {
                index: n.start,
                count: n.count,
            }
        } else {
            Child {
                index: collapse(bin, k, out),
                count: 0,
            }
        };
        let node = &mut out[me as usize];
        for a in 0..3 {
            node.lo[a][lane] = axis_of(n.bounds.lo, a);
            node.hi[a][lane] = axis_of(n.bounds.hi, a);
        }
        node.child[lane] = child;
    }
    me
}

/// Builds the binary node over `order` (indices into `bounds` and their `centres`) and,
/// depth first, those below it; returns its index.
fn build_node(
    bounds: &[Aabb],
    centres: &[V3],
    order: &mut [u32],
    offset: usize,
    nodes: &mut Vec<Node>,
) -> u32 {
    let me = nodes.len() as u32;
    let all = order
        .iter()
        .fold(Aabb::EMPTY, |b, &i| b.join(bounds[i as usize]));
    let cent = order
        .iter()
        .fold(Aabb::EMPTY, |b, &i| b.grow(centres[i as usize]));
    nodes.push(Node {
        bounds: all,
        start: offset as u32,
        count: order.len() as u32,
    });
    if order.len() <= LEAF {
        return me;
    }
    // Exact SAH: every split of the primitives sorted by centroid along each axis.
    let mut best: Option<(f32, usize, usize)> = None; // cost, axis, left count
    let mut right_area = vec![0.0f32; order.len()];
    let mut sorted_by = None;
    for axis in 0..3 {
        if axis_of(cent.hi, axis) - axis_of(cent.lo, axis) < 1e-9 {
            continue;
        }
        sort_by_centre(order, centres, axis);
        sorted_by = Some(axis);
        let mut r = Aabb::EMPTY;
        for k in (1..order.len()).rev() {
            r = r.join(bounds[order[k] as usize]);
            right_area[k] = r.half_area();
        }
        let mut l = Aabb::EMPTY;
        for k in 1..order.len() {
            l = l.join(bounds[order[k - 1] as usize]);
            let cost = l.half_area() * k as f32 + right_area[k] * (order.len() - k) as f32;
            if best.is_none_or(|b| cost < b.0) {
                best = Some((cost, axis, k));
            }
        }
    }
    let Some((cost, axis, mid)) = best else {
        return me; // all centroids coincide: one leaf
    };
    if order.len() <= 4 && cost >= all.half_area() * order.len() as f32 {
        return me;
    }
    if sorted_by != Some(axis) {
        sort_by_centre(order, centres, axis);
    }
    let (left, right) = order.split_at_mut(mid);
    build_node(bounds, centres, left, offset, nodes);
    let second = build_node(bounds, centres, right, offset + mid, nodes);
    nodes[me as usize].start = second;
    nodes[me as usize].count = 0;
    me
}

/// Sorts `order` by `centres` along `axis`, ties by index: the order depends on the axis
/// alone, so a tree is deterministic and a sort already done need not be repeated.
fn sort_by_centre(order: &mut [u32], centres: &[V3], axis: usize) {
    order.sort_unstable_by(|&a, &b| {
        let (ca, cb) = (
            axis_of(centres[a as usize], axis),
            axis_of(centres[b as usize], axis),
        );
        ca.total_cmp(&cb).then(a.cmp(&b))
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::shape::torus;

    #[test]
    fn bvh_finds_the_same_hits_as_a_linear_scan() {
        let mut prims = torus(V3(0.0, 0.0, 0.0), 1.0, 0.3, 25.0);
        prims.extend(torus(V3(0.5, 0.3, 0.2), 0.6, 0.2, -40.0));
        prims.push(Prim::Sphere {
            c: V3(0.0, 0.0, 0.0),
            r: 0.5,
        });
        let bvh = Bvh::build(&prims);
        let mut rng = crate::rng::Rng::new(3, 4);
        for _ in 0..2000 {
            let o = V3(
                rng.uniform() * 6.0 - 3.0,
                rng.uniform() * 6.0 - 3.0,
                rng.uniform() * 6.0 - 3.0,
            );
            let target = V3(
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
            );
            let d = (target - o).norm();
            let linear = prims
                .iter()
                .enumerate()
                .filter_map(|(i, p)| p.intersect(o, d, 1e-4, f32::INFINITY).map(|h| (i, h.t)))
                .min_by(|a, b| a.1.total_cmp(&b.1));
            let fast = bvh
                .intersect(&prims, o, d, 1e-4, f32::INFINITY)
                .map(|(i, h)| (i, h.t));
            assert_eq!(linear.map(|h| h.1), fast.map(|h| h.1));
            assert_eq!(linear.is_some(), bvh.occluded(o, d, f32::INFINITY, &[]));
        }
    }

    #[test]
    fn four_wide_bvh_finds_the_brute_force_closest_hit_on_random_triangles_and_spheres() {
        let mut rng = crate::rng::Rng::new(7, 11);
        let mut u = |a: f32, b: f32| a + (b - a) * rng.uniform();
        let mut prims = Vec::new();
        for _ in 0..300 {
            let p0 = V3(u(-2.0, 2.0), u(-2.0, 2.0), u(-2.0, 2.0));
            let e1 = V3(u(-0.4, 0.4), u(-0.4, 0.4), u(-0.4, 0.4));
            let e2 = V3(u(-0.4, 0.4), u(-0.4, 0.4), u(-0.4, 0.4));
            prims.push(Prim::Triangle { p0, e1, e2 });
        }
        for _ in 0..40 {
            let c = V3(u(-2.0, 2.0), u(-2.0, 2.0), u(-2.0, 2.0));
            prims.push(Prim::Sphere { c, r: u(0.02, 0.3) });
        }
        // Axis-aligned quads: zero-thickness boxes and rays along the axes.
        prims.push(Prim::Quad {
            p: V3(-1.0, 0.5, -1.0),
            e1: V3(2.0, 0.0, 0.0),
            e2: V3(0.0, 0.0, 2.0),
        });
        let bvh = Bvh::build(&prims);
        assert!(bvh.nodes.len() > 10);
        let mut hits = 0;
        for n in 0..5000 {
            let o = V3(u(-3.0, 3.0), u(-3.0, 3.0), u(-3.0, 3.0));
            let d = if n % 10 == 0 {
                // Along an axis: zero direction components (infinite inverses).
                [V3(1.0, 0.0, 0.0), V3(0.0, -1.0, 0.0), V3(0.0, 0.0, 1.0)][n % 3]
            } else {
                V3(u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0)).norm()
            };
            let t_max = if n % 4 == 0 {
                u(0.5, 4.0)
            } else {
                f32::INFINITY
            };
            let brute = prims
                .iter()
                .enumerate()
                .filter_map(|(i, p)| p.hit_t(o, d, 1e-4, t_max).map(|t| (i, t)))
                .min_by(|a, b| a.1.total_cmp(&b.1));
            let fast = bvh
                .intersect(&prims, o, d, 1e-4, t_max)
                .map(|(i, h)| (i, h.t));
            assert_eq!(brute, fast, "ray {n}");
            assert_eq!(brute.is_some(), bvh.occluded(o, d, t_max, &[]), "ray {n}");
            if let Some((i, _)) = brute {
                hits += 1;
                // Skipping the only primitive on the segment leaves it unblocked.
                let others = prims
                    .iter()
                    .enumerate()
                    .any(|(j, p)| j != i && p.hit_t(o, d, 0.0, t_max).is_some());
                assert_eq!(others, bvh.occluded(o, d, t_max, &[i]), "ray {n}");
            }
        }
        assert!(hits > 500, "{hits}");
    }

    #[test]
    fn single_leaf_and_empty_hierarchies() {
        let prims = vec![Prim::Sphere {
            c: V3(0.0, 0.0, 5.0),
            r: 1.0,
        }];
        let bvh = Bvh::build(&prims);
        let hit = bvh.intersect(
            &prims,
            V3(0.0, 0.0, 0.0),
            V3(0.0, 0.0, 1.0),
            1e-4,
            f32::INFINITY,
        );
        assert_eq!(hit.map(|(i, h)| (i, h.t)), Some((0, 4.0)));
        let empty = Bvh::build(&[]);
        assert!(empty
            .intersect(&[], V3(0.0, 0.0, 0.0), V3(0.0, 0.0, 1.0), 0.0, 1.0)
            .is_none());
        assert!(!empty.occluded(V3(0.0, 0.0, 0.0), V3(0.0, 0.0, 1.0), 1.0, &[]));
    }
}
