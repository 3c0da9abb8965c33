//! An implicit, balanced kd-tree over photon positions: the photons themselves are
//! reordered so that every subrange `[lo, hi)` has its splitting photon at the middle,
//! with one byte recording the split axis. Splitting by count (median index), never by
//! value, keeps the depth at ⌈log₂ n⌉ even for a million coincident photons.
//!
//! Subranges of at most [`LEAF`] photons are not split further: a query scans them in
//! order (contiguous memory, no branch per level), which costs fewer visits than the last
//! four levels of single-photon nodes would.

use glam::Vec3;

/// Subranges shorter than this are built on the current thread.
const PARALLEL_CUTOFF: usize = 1 << 14;

/// Subranges of at most this many photons are leaves, scanned in full by a query (their
/// axis bytes are unused).
pub const LEAF: usize = 16;
// A split range holds more than LEAF ≥ 2 photons, so both halves beside its median are
// non-empty: the searches push a far side without checking it.
const _: () = assert!(LEAF >= 2);
// A leaf's hits fit one u32 bit mask (see `scan_leaf`).
const _: () = assert!(LEAF <= 32);

/// The offset from `q` to `p` and its squared length, the one distance every search uses.
#[inline(always)]
fn offset_dist2(p: [f32; 3], q: [f32; 3]) -> ([f32; 3], f32) {
    let d = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
    (d, d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
}

/// `x`'s place in `f32::total_cmp`'s order as an unsigned key: keys compare as the
/// floats do under `total_cmp` (−NaN < −∞ < … < −0 < +0 < … < +∞ < NaN).
#[inline(always)]
fn order_key(x: f32) -> u32 {
    let b = x.to_bits();
    // total_cmp's own flip of the magnitude bits of negatives, then the sign flipped so
    // that the signed order becomes the unsigned one.
    (b ^ ((((b as i32) >> 31) as u32) >> 1)) ^ 0x8000_0000
}

/// The float of an [`order_key`].
#[inline(always)]
fn from_order_key(k: u32) -> f32 {
    let b = k ^ 0x8000_0000;
    f32::from_bits(b ^ ((((b as i32) >> 31) as u32) >> 1))
}

/// Computes the kd order: returns (permutation, axis per position in the new order).
pub fn build_order(positions: &[[f32; 3]]) -> (Vec<u32>, Vec<u8>) {
    // Points travel with their index (16 bytes each), so the selections compare memory
    // they already hold instead of chasing an index per comparison; coordinates as
    // `order_key`s, so that a comparison (coordinate, then index: ties split by count) is
    // one 64-bit integer comparison. The keys, the bounds and the permutation are computed
    // on every thread (serial, they left the other core idle around the build's parallel
    // halves).
    use rayon::prelude::*;
    let mut items: Vec<([u32; 3], u32)> = positions
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            (
                [order_key(p[0]), order_key(p[1]), order_key(p[2])],
                i as u32,
            )
        })
        .collect();
    let mut axes = vec![0u8; positions.len()];
    let bounds = positions.par_chunks(PARALLEL_CUTOFF).map(bounds_of).reduce(
        || ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]),
        |(lo_a, hi_a), (lo_b, hi_b)| {
            (
                std::array::from_fn(|a| lo_a[a].min(lo_b[a])),
                std::array::from_fn(|a| hi_a[a].max(hi_b[a])),
            )
        },
    );
    build(&mut items, &mut axes, bounds);
    (items.par_iter().map(|it| it.1).collect(), axes)
}

/// The smallest box holding `positions` (lowest and highest corner).
fn bounds_of(positions: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for p in positions {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (lo, hi)
}

/// Splits `items` at its median along the longest axis of `bounds` (the parent's box cut
/// at the parent's split: no rescan of the points per node).
fn build(items: &mut [([u32; 3], u32)], axes: &mut [u8], bounds: ([f32; 3], [f32; 3])) {
    let n = items.len();
    if n <= LEAF {
        return;
    }
    let (lo, hi) = bounds;
    let ext = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let axis = if ext[0] >= ext[1] && ext[0] >= ext[2] {
        0
    } else if ext[1] >= ext[2] {
        1
    } else {
        2
    };
    let mid = n / 2;
    // One selection per axis, so that each compares a fixed field (no indexing by a
    // run-time axis per comparison).
    fn key<const A: usize>(a: &([u32; 3], u32)) -> u64 {
        ((a.0[A] as u64) << 32) | a.1 as u64
    }
    match axis {
        0 => items.select_nth_unstable_by_key(mid, key::<0>),
        1 => items.select_nth_unstable_by_key(mid, key::<1>),
        _ => items.select_nth_unstable_by_key(mid, key::<2>),
    };
    axes[mid] = axis as u8;
    let split = from_order_key(items[mid].0[axis]);
    let (mut left_hi, mut right_lo) = (hi, lo);
    left_hi[axis] = split;
    right_lo[axis] = split;
    let (left, rest) = items.split_at_mut(mid);
    let right = &mut rest[1..];
    let (al, arest) = axes.split_at_mut(mid);
    let ar = &mut arest[1..];
    if n > PARALLEL_CUTOFF {
        rayon::join(
            || build(left, al, (lo, left_hi)),
            || build(right, ar, (right_lo, hi)),
        );
    } else {
        build(left, al, (lo, left_hi));
        build(right, ar, (right_lo, hi));
    }
}

/// Calls `f(i, distance²)` for the leaf's positions within √`r2` of `p`, in order. The
/// distances are computed first and the hits marked in a bit mask, so the scan has no
/// data-dependent branch per photon (about one in seven of a range search's leaf
/// photons is inside: a branch on each is mispredicted at every change).
#[inline(always)]
fn scan_leaf(leaf: &[[f32; 3]], p: [f32; 3], r2: f32, mut f: impl FnMut(usize, f32)) {
    debug_assert!(leaf.len() <= LEAF);
    let mut d2s = [0.0f32; LEAF];
    let mut mask = 0u32;
    for (i, q) in leaf.iter().enumerate() {
        let (_, d2) = offset_dist2(p, *q);
        d2s[i] = d2;
        mask |= u32::from(d2 <= r2) << i;
    }
    while mask != 0 {
        let i = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        f(i, d2s[i]);
    }
}

/// Calls `f(index, distance²)` for every position within distance √`r2` of `p`.
/// `positions` must be in kd order (see [`build_order`]).
#[inline]
pub fn for_each_within(
    positions: &[[f32; 3]],
    axes: &[u8],
    p: Vec3,
    r2: f32,
    mut f: impl FnMut(usize, f32),
) {
    let p = p.to_array();
    let dist2 = |q: [f32; 3]| offset_dist2(p, q);
    let mut stack = [(0usize, 0usize); 64];
    let mut sp = 0;
    let (mut lo, mut hi) = (0usize, positions.len());
    loop {
        if hi - lo > LEAF {
            let mid = (lo + hi) / 2;
            let (d, d2) = dist2(positions[mid]);
            if d2 <= r2 {
                f(mid, d2);
            }
            let delta = d[axes[mid] as usize];
            // Visit the near side now, keep the far side if the sphere crosses the plane.
            let (near, far) = if delta <= 0.0 {
                ((lo, mid), (mid + 1, hi))
            } else {
                ((mid + 1, hi), (lo, mid))
            };
            if delta * delta <= r2 && sp < stack.len() {
                stack[sp] = far;
                sp += 1;
            }
            (lo, hi) = near;
            continue;
        }
        scan_leaf(&positions[lo..hi], p, r2, |i, d2| f(lo + i, d2));
        if sp == 0 {
            break;
        }
        sp -= 1;
        (lo, hi) = stack[sp];
    }
}

/// The nearest position within distance √`r2_max` of `p` that passes `accept`, as
/// (distance², index), or `None`. The near side is visited first, so the radius drops to
/// the nearest point's distance almost at once and prunes the rest of the tree; of equally
/// near points the first visited wins.
pub fn nearest_within(
    positions: &[[f32; 3]],
    axes: &[u8],
    p: Vec3,
    r2_max: f32,
    accept: impl Fn(usize) -> bool,
) -> Option<(f32, u32)> {
    let p = p.to_array();
    let mut best = None;
    let mut r2 = r2_max;
    let mut offer = |i: usize, d2: f32, r2: &mut f32| {
        if d2 < *r2 && accept(i) {
            *r2 = d2;
            best = Some((d2, i as u32));
        }
    };
    let mut stack = [(0usize, 0usize, 0f32); 64];
    let mut sp = 0;
    let (mut lo, mut hi) = (0usize, positions.len());
    loop {
        if hi - lo > LEAF {
            let mid = (lo + hi) / 2;
            let (d, d2) = offset_dist2(p, positions[mid]);
            offer(mid, d2, &mut r2);
            let delta = d[axes[mid] as usize];
            let (near, far) = if delta <= 0.0 {
                ((lo, mid), (mid + 1, hi))
            } else {
                ((mid + 1, hi), (lo, mid))
            };
            if delta * delta < r2 && sp < stack.len() {
                stack[sp] = (far.0, far.1, delta * delta);
                sp += 1;
            }
            (lo, hi) = near;
            continue;
        }
        for (i, q) in positions[lo..hi].iter().enumerate() {
            offer(lo + i, offset_dist2(p, *q).1, &mut r2);
        }
        // The next kept side the radius still reaches (it may have shrunk since).
        let mut next = None;
        while sp > 0 && next.is_none() {
            sp -= 1;
            let (a, b, plane2) = stack[sp];
            if plane2 < r2 {
                next = Some((a, b));
            }
        }
        match next {
            Some(range) => (lo, hi) = range,
            None => break,
        }
    }
    best
}

/// Distance to the k-th nearest position (or to the farthest, if fewer than k).
pub fn kth_nearest_distance(positions: &[[f32; 3]], axes: &[u8], p: Vec3, k: usize) -> f32 {
    if positions.is_empty() || k == 0 {
        return 0.0;
    }
    // One exact traversal with a bounded max-heap of the k smallest distances.
    let mut heap: std::collections::BinaryHeap<OrdF32> = std::collections::BinaryHeap::new();
    let mut r2 = f32::INFINITY;
    kth_rec(
        positions,
        axes,
        p.to_array(),
        k,
        0,
        positions.len(),
        &mut heap,
        &mut r2,
    );
    heap.peek().map(|d| d.0.sqrt()).unwrap_or(0.0)
}

/// An f32 with a total order, for the k-nearest heap.
struct OrdF32(f32);
impl PartialEq for OrdF32 {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o).is_eq()
    }
}
impl Eq for OrdF32 {}
impl PartialOrd for OrdF32 {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for OrdF32 {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&o.0)
    }
}

#[allow(clippy::too_many_arguments)]
fn kth_rec(
    pos: &[[f32; 3]],
    axes: &[u8],
    p: [f32; 3],
    k: usize,
    lo: usize,
    hi: usize,
    heap: &mut std::collections::BinaryHeap<OrdF32>,
    r2: &mut f32,
) {
    let dist2 = |q: [f32; 3]| offset_dist2(p, q);
    let mut offer = |d2: f32, heap: &mut std::collections::BinaryHeap<OrdF32>| {
        if heap.len() < k {
            heap.push(OrdF32(d2));
            if heap.len() == k {
                *r2 = heap.peek().map(|v| v.0).unwrap_or(f32::INFINITY);
            }
        } else if d2 < *r2 {
            heap.pop();
            heap.push(OrdF32(d2));
            *r2 = heap.peek().map(|v| v.0).unwrap_or(f32::INFINITY);
        }
    };
    if hi - lo <= LEAF {
        for q in &pos[lo..hi] {
            offer(dist2(*q).1, heap);
        }
        return;
    }
    let mid = (lo + hi) / 2;
    let (d, d2) = dist2(pos[mid]);
    offer(d2, heap);
    let delta = d[axes[mid] as usize];
    let (near, far) = if delta <= 0.0 {
        ((lo, mid), (mid + 1, hi))
    } else {
        ((mid + 1, hi), (lo, mid))
    };
    kth_rec(pos, axes, p, k, near.0, near.1, heap, r2);
    if delta * delta <= *r2 {
        kth_rec(pos, axes, p, k, far.0, far.1, heap, r2);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Purpose, Rng};

    fn ordered(points: &[[f32; 3]]) -> (Vec<[f32; 3]>, Vec<u8>) {
        let (order, axes) = build_order(points);
        (order.iter().map(|&i| points[i as usize]).collect(), axes)
    }

    fn brute(points: &[[f32; 3]], p: Vec3, r2: f32) -> usize {
        points
            .iter()
            .filter(|q| (Vec3::from_array(**q) - p).length_squared() <= r2)
            .count()
    }

    #[test]
    fn order_keys_order_as_total_cmp_and_invert() {
        let specials = [
            f32::NEG_INFINITY,
            -f32::MAX,
            -1.0,
            -f32::MIN_POSITIVE,
            -1e-45,
            -0.0,
            0.0,
            1e-45,
            f32::MIN_POSITIVE,
            1.0,
            f32::MAX,
            f32::INFINITY,
            f32::NAN,
            -f32::NAN,
        ];
        let mut rng = Rng::stream(5, 0, 0, Purpose::Photon);
        let xs: Vec<f32> = specials
            .into_iter()
            .chain((0..2000).map(|_| f32::from_bits(rng.next_u32())))
            .collect();
        for &a in &xs {
            assert_eq!(from_order_key(order_key(a)).to_bits(), a.to_bits());
            for &b in &xs[..64] {
                assert_eq!(order_key(a).cmp(&order_key(b)), a.total_cmp(&b), "{a} {b}");
            }
        }
    }

    /// The build before the keys (kept as the reference): selections by `total_cmp`, ties
    /// by index.
    fn reference_order(positions: &[[f32; 3]]) -> (Vec<u32>, Vec<u8>) {
        fn build(items: &mut [([f32; 3], u32)], axes: &mut [u8], (lo, hi): ([f32; 3], [f32; 3])) {
            let n = items.len();
            if n <= LEAF {
                return;
            }
            let ext = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
            let axis = if ext[0] >= ext[1] && ext[0] >= ext[2] {
                0
            } else if ext[1] >= ext[2] {
                1
            } else {
                2
            };
            let mid = n / 2;
            items.select_nth_unstable_by(mid, |a, b| {
                a.0[axis].total_cmp(&b.0[axis]).then(a.1.cmp(&b.1))
            });
            axes[mid] = axis as u8;
            let split = items[mid].0[axis];
            let (mut left_hi, mut right_lo) = (hi, lo);
            left_hi[axis] = split;
            right_lo[axis] = split;
            let (left, rest) = items.split_at_mut(mid);
            let (al, arest) = axes.split_at_mut(mid);
            build(left, al, (lo, left_hi));
            build(&mut rest[1..], &mut arest[1..], (right_lo, hi));
        }
        let mut items: Vec<_> = positions
            .iter()
            .enumerate()
            .map(|(i, p)| (*p, i as u32))
            .collect();
        let mut axes = vec![0u8; positions.len()];
        build(&mut items, &mut axes, bounds_of(positions));
        (items.iter().map(|it| it.1).collect(), axes)
    }

    #[test]
    fn the_keyed_build_orders_exactly_as_the_comparison_build() {
        // Spread points, points on a grid of few values (many ties, ±0), and enough of
        // them for the parallel split.
        let mut rng = Rng::stream(9, 0, 0, Purpose::Photon);
        let spread: Vec<[f32; 3]> = (0..3000)
            .map(|_| {
                [
                    rng.next_f32() - 0.5,
                    100.0 * rng.next_f32(),
                    -rng.next_f32(),
                ]
            })
            .collect();
        let ties: Vec<[f32; 3]> = (0..40_000u32)
            .map(|i| {
                let v = |k: u32| [-1.0, -0.0, 0.0, 0.5][(k % 4) as usize];
                [v(i), v(i / 4), v(i / 16 + i % 3)]
            })
            .collect();
        for points in [&spread, &ties] {
            assert_eq!(build_order(points), reference_order(points));
        }
    }

    #[test]
    fn range_queries_match_brute_force() {
        let mut rng = Rng::stream(5, 0, 0, Purpose::Photon);
        let pts: Vec<[f32; 3]> = (0..20_000)
            .map(|_| [rng.next_f32(), rng.next_f32() * 0.1, rng.next_f32()])
            .collect();
        let (sorted, axes) = ordered(&pts);
        for _ in 0..200 {
            let p = Vec3::new(rng.next_f32(), rng.next_f32() * 0.1, rng.next_f32());
            let r2 = 0.003;
            let mut n = 0;
            for_each_within(&sorted, &axes, p, r2, |_, _| n += 1);
            assert_eq!(n, brute(&pts, p, r2));
        }
    }

    /// The brute-force answer to [`nearest_within`]: the least distance² below `r2_max`
    /// among accepted points, and every index at that distance.
    fn brute_nearest(
        pts: &[[f32; 3]],
        p: Vec3,
        r2_max: f32,
        keep: impl Fn(usize) -> bool,
    ) -> Option<(f32, Vec<u32>)> {
        let d2s: Vec<(f32, u32)> = (0..pts.len())
            .filter(|&i| keep(i))
            .map(|i| ((Vec3::from_array(pts[i]) - p).length_squared(), i as u32))
            .filter(|&(d2, _)| d2 < r2_max)
            .collect();
        let least = d2s.iter().map(|d| d.0).min_by(f32::total_cmp)?;
        Some((
            least,
            d2s.iter().filter(|d| d.0 == least).map(|d| d.1).collect(),
        ))
    }

    #[test]
    fn nearest_matches_brute_force_with_a_filter_and_a_cap() {
        let mut rng = Rng::stream(6, 0, 0, Purpose::Photon);
        let pts: Vec<[f32; 3]> = (0..20_000)
            .map(|_| [rng.next_f32(), rng.next_f32() * 0.1, rng.next_f32()])
            .collect();
        let (sorted, axes) = ordered(&pts);
        let (mut capped, mut none) = (0, 0);
        for trial in 0..400 {
            let p = Vec3::new(rng.next_f32(), rng.next_f32() * 0.1, rng.next_f32());
            // Caps from far below the spacing (often nothing within) to the whole box.
            let r2_max = [1e-4, 5e-4, 2e-3, 1.0][trial % 4];
            // Keep about one photon in five (by its position), as a surface test would.
            let keep = |i: usize| ((sorted[i][0] * 1e4) as u32).is_multiple_of(5);
            let got = nearest_within(&sorted, &axes, p, r2_max, keep);
            let want = brute_nearest(&sorted, p, r2_max, keep);
            match (got, want) {
                (None, None) => none += 1,
                (Some((d2, i)), Some((least, at))) => {
                    assert_eq!(d2, least, "trial {trial}");
                    assert!(at.contains(&i), "trial {trial}: {i} not in {at:?}");
                    capped += usize::from(r2_max < 1.0);
                }
                (got, want) => panic!("trial {trial}: {got:?} against {want:?}"),
            }
        }
        // Both outcomes were exercised under a cap.
        assert!(
            none > 20 && capped > 20,
            "{none} empty, {capped} found under a cap"
        );
    }

    #[test]
    fn every_size_around_the_leaf_size_answers_as_brute_force_does() {
        let mut rng = Rng::stream(7, 0, 0, Purpose::Photon);
        for n in 0..(4 * LEAF + 3) {
            let pts: Vec<[f32; 3]> = (0..n)
                .map(|_| [rng.next_f32(), rng.next_f32(), rng.next_f32()])
                .collect();
            let (sorted, axes) = ordered(&pts);
            for _ in 0..20 {
                let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                let r2 = 0.1 * rng.next_f32();
                let mut seen = Vec::new();
                for_each_within(&sorted, &axes, p, r2, |i, d2| {
                    assert_eq!(d2, (Vec3::from_array(sorted[i]) - p).length_squared());
                    seen.push(i)
                });
                seen.sort();
                seen.dedup();
                assert_eq!(seen.len(), brute(&pts, p, r2), "{n} points");
                let got = nearest_within(&sorted, &axes, p, 1.0, |_| true).map(|g| g.0);
                let want = brute_nearest(&pts, p, 1.0, |_| true).map(|w| w.0);
                assert_eq!(got, want, "{n} points");
                let k = 1 + n / 3;
                let kth = kth_nearest_distance(&sorted, &axes, p, k);
                let mut all: Vec<f32> = pts
                    .iter()
                    .map(|q| (Vec3::from_array(*q) - p).length_squared())
                    .collect();
                all.sort_by(f32::total_cmp);
                let want_kth = all.get(k.min(n).wrapping_sub(1)).map_or(0.0, |d| d.sqrt());
                assert_eq!(kth, want_kth, "{n} points, k {k}");
            }
        }
    }

    #[test]
    fn empty_single_and_million_coincident_photons() {
        let (s, a) = ordered(&[]);
        let mut n = 0;
        for_each_within(&s, &a, Vec3::ZERO, 1.0, |_, _| n += 1);
        assert_eq!(n, 0);
        assert_eq!(kth_nearest_distance(&s, &a, Vec3::ZERO, 5), 0.0);

        let (s, a) = ordered(&[[1.0, 2.0, 3.0]]);
        for_each_within(&s, &a, Vec3::new(1.0, 2.0, 3.0), 0.0, |_, _| n += 1);
        assert_eq!(n, 1);

        // kiddo#475 / CGAL#3077: many identical points broke other trees.
        let same = vec![[0.5f32, 0.5, 0.5]; 1_000_000];
        let (s, a) = ordered(&same);
        let mut n = 0;
        for_each_within(&s, &a, Vec3::splat(0.5), 1e-12, |_, _| n += 1);
        assert_eq!(n, 1_000_000);
        // A line and a plane of points.
        let line: Vec<[f32; 3]> = (0..100_000).map(|i| [i as f32, 0.0, 0.0]).collect();
        let (s, a) = ordered(&line);
        let mut n = 0;
        for_each_within(&s, &a, Vec3::new(500.0, 0.0, 0.0), 10.5 * 10.5, |_, _| {
            n += 1
        });
        assert_eq!(n, 21);
        let d = kth_nearest_distance(&s, &a, Vec3::new(500.0, 0.0, 0.0), 3);
        assert!((d - 1.0).abs() < 1e-6, "{d}");
    }
}
