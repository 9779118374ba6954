//! A bounding volume hierarchy over all primitives of a scene (binned SAH build,
//! ordered stack traversal).

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
    /// Split axis of an interior node.
    axis: u8,
}

/// The hierarchy. Primitive indices refer to the slice it was built from.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    order: Vec<u32>,
    /// The primitives in leaf order, in the form the intersection test wants.
    packed: Vec<Packed>,
}

const BINS: usize = 12;
const LEAF: usize = 2;

fn axis_of(v: V3, a: usize) -> f32 {
    [v.0, v.1, v.2][a]
}

impl Bvh {
    /// Builds over `prims`.
    pub fn build(prims: &[Prim]) -> Self {
        let bounds: Vec<Aabb> = prims.iter().map(Prim::bounds).collect();
        let mut order: Vec<u32> = (0..prims.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * prims.len().max(1));
        if !prims.is_empty() {
            build_node(&bounds, &mut order, 0, &mut nodes);
        }
        let packed = order
            .iter()
            .map(|&i| Packed::new(&prims[i as usize]))
            .collect();
        Bvh {
            nodes,
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
        if self.nodes.is_empty() {
            return None;
        }
        let inv = V3(1.0 / d.0, 1.0 / d.1, 1.0 / d.2);
        let neg = [d.0 < 0.0, d.1 < 0.0, d.2 < 0.0];
        let mut best = None;
        let mut stack = [0u32; 64];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let node = &self.nodes[stack[sp] as usize];
            if !slab(&node.bounds, o, inv, t_min, t_max) {
                continue;
            }
            if node.count > 0 {
                let s = node.start as usize;
                for k in s..s + node.count as usize {
                    if let Some(t) = self.packed[k].hit_t(o, d, t_min, t_max) {
                        t_max = t;
                        best = Some(self.order[k] as usize);
                    }
                }
            } else {
                let first = stack[sp] + 1;
                let second = node.start;
                // Visit the nearer child first: push it last.
                let (near, far) = if neg[node.axis as usize] {
                    (second, first)
                } else {
                    (first, second)
                };
                stack[sp] = far;
                stack[sp + 1] = near;
                sp += 2;
            }
        }
        best.map(|i| (i, prims[i].surface(o + d * t_max, t_max)))
    }

    /// Whether anything blocks the segment (t_min, t_max), skipping primitive `skip`.
    pub fn occluded(&self, o: V3, d: V3, t_max: f32, skip: &[usize]) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let inv = V3(1.0 / d.0, 1.0 / d.1, 1.0 / d.2);
        let mut stack = [0u32; 64];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let idx = stack[sp];
            let node = &self.nodes[idx as usize];
            if !slab(&node.bounds, o, inv, 0.0, t_max) {
                continue;
            }
            if node.count > 0 {
                let s = node.start as usize;
                for k in s..s + node.count as usize {
                    if !skip.contains(&(self.order[k] as usize))
                        && self.packed[k].hit_t(o, d, 0.0, t_max).is_some()
                    {
                        return true;
                    }
                }
            } else {
                stack[sp] = idx + 1;
                stack[sp + 1] = node.start;
                sp += 2;
            }
        }
        false
    }
}

fn slab(b: &Aabb, o: V3, inv: V3, t_min: f32, t_max: f32) -> bool {
    let (mut t0, mut t1) = (t_min, t_max);
    for a in 0..3 {
        let (lo, hi) = (axis_of(b.lo, a), axis_of(b.hi, a));
        let (oa, ia) = (axis_of(o, a), axis_of(inv, a));
        let (mut n, mut f) = ((lo - oa) * ia, (hi - oa) * ia);
        if n > f {
            std::mem::swap(&mut n, &mut f);
        }
        // NaN (0 * inf) compares false and leaves the interval as it was.
        if n > t0 {
            t0 = n;
        }
        if f < t1 {
            t1 = f;
        }
        if t0 > t1 {
            return false;
        }
    }
    true
}

fn build_node(bounds: &[Aabb], order: &mut [u32], offset: usize, nodes: &mut Vec<Node>) -> u32 {
    let me = nodes.len() as u32;
    let all = order
        .iter()
        .fold(Aabb::EMPTY, |b, &i| b.join(bounds[i as usize]));
    let cent = order
        .iter()
        .fold(Aabb::EMPTY, |b, &i| b.grow(bounds[i as usize].centre()));
    nodes.push(Node {
        bounds: all,
        start: offset as u32,
        count: order.len() as u32,
        axis: 0,
    });
    if order.len() <= LEAF {
        return me;
    }
    // Binned SAH over the centroid box's axes.
    let mut best: Option<(f32, usize, usize)> = None; // cost, axis, bin boundary
    for axis in 0..3 {
        let (lo, hi) = (axis_of(cent.lo, axis), axis_of(cent.hi, axis));
        if hi - lo < 1e-9 {
            continue;
        }
        let bin_of = |i: u32| {
            let c = axis_of(bounds[i as usize].centre(), axis);
            (((c - lo) / (hi - lo) * BINS as f32) as usize).min(BINS - 1)
        };
        let mut bb = [Aabb::EMPTY; BINS];
        let mut cnt = [0usize; BINS];
        for &i in order.iter() {
            let b = bin_of(i);
            bb[b] = bb[b].join(bounds[i as usize]);
            cnt[b] += 1;
        }
        for split in 1..BINS {
            let (mut l, mut r) = (Aabb::EMPTY, Aabb::EMPTY);
            let (mut nl, mut nr) = (0, 0);
            for k in 0..split {
                l = l.join(bb[k]);
                nl += cnt[k];
            }
            for k in split..BINS {
                r = r.join(bb[k]);
                nr += cnt[k];
            }
            if nl == 0 || nr == 0 {
                continue;
            }
            let cost = l.half_area() * nl as f32 + r.half_area() * nr as f32;
            if best.is_none_or(|b| cost < b.0) {
                best = Some((cost, axis, split));
            }
        }
    }
    let Some((cost, axis, split)) = best else {
        return me; // all centroids coincide: one leaf
    };
    if order.len() <= 4 && cost >= all.half_area() * order.len() as f32 {
        return me;
    }
    let (lo, hi) = (axis_of(cent.lo, axis), axis_of(cent.hi, axis));
    let mid = partition(order, |i| {
        let c = axis_of(bounds[i as usize].centre(), axis);
        ((((c - lo) / (hi - lo)) * BINS as f32) as usize).min(BINS - 1) < split
    });
    let (left, right) = order.split_at_mut(mid);
    build_node(bounds, left, offset, nodes);
    let second = build_node(bounds, right, offset + mid, nodes);
    nodes[me as usize].start = second;
    nodes[me as usize].count = 0;
    nodes[me as usize].axis = axis as u8;
    me
}

fn partition(v: &mut [u32], pred: impl Fn(u32) -> bool) -> usize {
    let mut k = 0;
    for i in 0..v.len() {
        if pred(v[i]) {
            v.swap(i, k);
            k += 1;
        }
    }
    k
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
}
