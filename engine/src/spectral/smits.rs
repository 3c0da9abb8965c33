//! Smits (1999) RGB → spectrum on a bin grid, and its exact inverse used by the compact
//! photon format.
//!
//! Smits' map is linear inside each of six branches (which channel is smallest, which is
//! largest). Binned, branch `k` is an N×3 matrix `B_k`: spectrum = B_k · (r, g, b). The
//! compact format stores, for a smooth photon flux `s`, the triplet `x` for which the
//! decoded spectrum `B_k x` has **exactly** the colour of `s` (its linear sRGB, hence its
//! XYZ): `x = A_k⁻¹ t` with `t` the colour of `s` and `A_k = Wᵀ B_k`, taking the branch `k`
//! whose region `x` falls in. Only metameric information is lost. Where no branch fits
//! (out of gamut, or N < 3 where `A_k` is singular) the triplet falls back to the colour's
//! coordinates in Smits' own RGB space (sRGB primaries, white E), clamped to ≥ 0.
//!
//! Decoding sums photons per branch (linear within a branch), then expands each branch
//! sum once: the same result as expanding every photon, at O(1) per photon.

use super::color::{SRGB_TO_XYZ, invert3, mul3};
use super::grid::BinGrid;
use super::tables::smits_basis;

/// Branch of Smits' algorithm for an RGB triple (the tie-breaking of the original).
#[inline]
pub fn branch(rgb: [f32; 3]) -> usize {
    let [r, g, b] = rgb;
    if r <= g && r <= b {
        if g <= b { 0 } else { 1 }
    } else if g <= r && g <= b {
        if r <= b { 2 } else { 3 }
    } else if r <= g {
        4
    } else {
        5
    }
}

#[derive(Clone, Debug)]
pub struct SmitsBins {
    n: usize,
    /// `cols[k][c]`: the spectrum multiplying channel c in branch k (N values).
    cols: [[Vec<f32>; 3]; 6],
    /// `A_k`: linear sRGB of the decoded spectrum as a function of the triplet.
    a: [[[f64; 3]; 3]; 6],
    /// Inverse of `A_k` (`None` where singular, as for N < 3).
    inv: [Option<[[f64; 3]; 3]>; 6],
    /// Per-bin weights to linear sRGB (copied from the grid).
    weights: Vec<[f32; 3]>,
    /// Linear sRGB → Smits' RGB space (sRGB primaries, white E), for the fallback.
    srgb_to_e: [[f64; 3]; 3],
}

impl SmitsBins {
    pub fn new(grid: &BinGrid) -> Self {
        let n = grid.len();
        let basis = smits_basis();
        // Bin means of the seven basis spectra: white, cyan, magenta, yellow, red, green, blue.
        let avg: Vec<Vec<f64>> = basis
            .iter()
            .map(|f| {
                (0..n)
                    .map(|i| {
                        let (a, b) = grid.bin_edges(i);
                        f.average(a, b)
                    })
                    .collect()
            })
            .collect();
        let (w, c, m, y, r, g, b) = (0, 1, 2, 3, 4, 5, 6);
        let lin = |terms: &[(usize, f64)]| -> Vec<f32> {
            (0..n)
                .map(|i| terms.iter().map(|&(s, k)| k * avg[s][i]).sum::<f64>() as f32)
                .collect()
        };
        let cols: [[Vec<f32>; 3]; 6] = [
            // r min, g ≤ b: rW + (g−r)C + (b−g)B
            [
                lin(&[(w, 1.0), (c, -1.0)]),
                lin(&[(c, 1.0), (b, -1.0)]),
                lin(&[(b, 1.0)]),
            ],
            // r min, b < g: rW + (b−r)C + (g−b)G
            [
                lin(&[(w, 1.0), (c, -1.0)]),
                lin(&[(g, 1.0)]),
                lin(&[(c, 1.0), (g, -1.0)]),
            ],
            // g min, r ≤ b: gW + (r−g)M + (b−r)B
            [
                lin(&[(m, 1.0), (b, -1.0)]),
                lin(&[(w, 1.0), (m, -1.0)]),
                lin(&[(b, 1.0)]),
            ],
            // g min, b < r: gW + (b−g)M + (r−b)R
            [
                lin(&[(r, 1.0)]),
                lin(&[(w, 1.0), (m, -1.0)]),
                lin(&[(m, 1.0), (r, -1.0)]),
            ],
            // b min, r ≤ g: bW + (r−b)Y + (g−r)G
            [
                lin(&[(y, 1.0), (g, -1.0)]),
                lin(&[(g, 1.0)]),
                lin(&[(w, 1.0), (y, -1.0)]),
            ],
            // b min, g < r: bW + (g−b)Y + (r−g)R
            [
                lin(&[(r, 1.0)]),
                lin(&[(y, 1.0), (r, -1.0)]),
                lin(&[(w, 1.0), (y, -1.0)]),
            ],
        ];
        let weights = grid.srgb_weights().to_vec();
        let a: [[[f64; 3]; 3]; 6] = std::array::from_fn(|k| {
            std::array::from_fn(|row| {
                std::array::from_fn(|col| {
                    (0..n)
                        .map(|i| weights[i][row] as f64 * cols[k][col][i] as f64)
                        .sum()
                })
            })
        });
        let inv = std::array::from_fn(|k| if n < 3 { None } else { invert3(&a[k]) });
        // Smits' space: sRGB primaries scaled so that (1,1,1) is white E (X = Y = Z).
        let s = mul3(
            &invert3(&SRGB_TO_XYZ).expect("sRGB matrix is invertible"),
            [1.0, 1.0, 1.0],
        );
        let mut e_to_xyz = SRGB_TO_XYZ;
        for row in &mut e_to_xyz {
            for (col, v) in row.iter_mut().enumerate() {
                *v *= s[col];
            }
        }
        let xyz_to_e = invert3(&e_to_xyz).expect("invertible");
        let srgb_to_e = mat_mul(&xyz_to_e, &SRGB_TO_XYZ);
        Self {
            n,
            cols,
            a,
            inv,
            weights,
            srgb_to_e,
        }
    }

    /// Expands a triplet to N bins (overwrites `out`).
    pub fn decode_into(&self, rgb: [f32; 3], out: &mut [f32]) {
        out.fill(0.0);
        self.add_branch(branch(rgb), rgb, out);
    }

    /// Adds `B_k · rgb` to `out`.
    pub fn add_branch(&self, k: usize, rgb: [f32; 3], out: &mut [f32]) {
        let [c0, c1, c2] = &self.cols[k];
        for i in 0..self.n {
            out[i] += rgb[0] * c0[i] + rgb[1] * c1[i] + rgb[2] * c2[i];
        }
    }

    /// The triplet whose decoded spectrum has the colour of `spd` (see the module docs).
    pub fn encode(&self, spd: &[f32]) -> [f32; 3] {
        let t = self.project(spd);
        let clamp = |x: [f64; 3]| {
            x.map(|v| {
                if v.is_finite() && v > 0.0 {
                    v as f32
                } else {
                    0.0
                }
            })
        };
        // The branch of the colour's coordinates in Smits' own space is almost always the
        // right one for a smooth flux: try it first, then the others.
        let naive = mul3(&self.srgb_to_e, t);
        let k0 = branch(naive.map(|v| v as f32));
        for k in std::iter::once(k0).chain((0..6).filter(|&k| k != k0)) {
            let Some(inv) = &self.inv[k] else { continue };
            let exact = mul3(inv, t);
            let x = clamp(exact);
            if branch(x) == k && x == clamp_exact(exact) {
                // Inside its own branch and non-negative: exact.
                return x;
            }
        }
        // Out of Smits' gamut (or N < 3): the candidate of nearest colour.
        let mut best = clamp(naive);
        let mut best_err = self.colour_error(best, t);
        for inv in self.inv.iter().flatten() {
            let x = clamp(mul3(inv, t));
            let err = self.colour_error(x, t);
            if err < best_err {
                best = x;
                best_err = err;
            }
        }
        best
    }

    /// Linear sRGB of `spd` in f64: Σ wᵢ·vᵢ per channel. Each product of two f32 is exact
    /// in f64; the sums run in four interleaved partial sums (independent chains the CPU
    /// overlaps, instead of one chain of N dependent additions per channel), so only the
    /// order of the f64 additions differs from a plain loop — far below an f32 ulp.
    fn project(&self, spd: &[f32]) -> [f64; 3] {
        let mut part = [[0.0f64; 3]; 4];
        let n = self.weights.len().min(spd.len());
        let done = 4 * (n / 4);
        for (w4, v4) in self.weights[..done]
            .chunks_exact(4)
            .zip(spd[..done].chunks_exact(4))
        {
            for ((p, w), &v) in part.iter_mut().zip(w4).zip(v4) {
                let v = v as f64;
                p[0] += w[0] as f64 * v;
                p[1] += w[1] as f64 * v;
                p[2] += w[2] as f64 * v;
            }
        }
        let mut t = [0.0f64; 3];
        for c in 0..3 {
            t[c] = (part[0][c] + part[1][c]) + (part[2][c] + part[3][c]);
        }
        for (w, &v) in self.weights[done..n].iter().zip(&spd[done..n]) {
            for c in 0..3 {
                t[c] += w[c] as f64 * v as f64;
            }
        }
        t
    }

    /// Linear sRGB of the decoded triplet, computed without expanding it.
    pub fn colour_of(&self, x: [f32; 3]) -> [f64; 3] {
        mul3(&self.a[branch(x)], x.map(f64::from))
    }

    fn colour_error(&self, x: [f32; 3], t: [f64; 3]) -> f64 {
        let c = self.colour_of(x);
        (0..3).map(|i| (c[i] - t[i]).powi(2)).sum()
    }
}

/// The f32 triplet of `x` without clamping (NaN stays NaN, so it never equals a clamp).
fn clamp_exact(x: [f64; 3]) -> [f32; 3] {
    x.map(|v| v as f32)
}

impl SmitsBins {
    /// Number of bins.
    pub fn len(&self) -> usize {
        self.n
    }

    pub fn is_empty(&self) -> bool {
        self.n == 0
    }
}

fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|r| std::array::from_fn(|c| (0..3).map(|k| a[r][k] * b[k][c]).sum()))
}

/// Per-branch sums of triplets, expanded once at the end (see the module docs).
#[derive(Clone, Copy, Debug, Default)]
pub struct BranchSums {
    sums: [[f32; 3]; 6],
    used: u8,
}

impl BranchSums {
    #[inline]
    pub fn add(&mut self, rgb: [f32; 3], weight: f32) {
        let k = branch(rgb);
        let s = &mut self.sums[k];
        s[0] += rgb[0] * weight;
        s[1] += rgb[1] * weight;
        s[2] += rgb[2] * weight;
        self.used |= 1 << k;
    }

    /// Adds the expanded sums to `out`.
    pub fn expand_into(&self, smits: &SmitsBins, out: &mut [f32]) {
        for k in 0..6 {
            if self.used & (1 << k) != 0 {
                smits.add_branch(k, self.sums[k], out);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Purpose, Rng};

    #[test]
    fn the_interleaved_projection_is_the_plain_sum_to_far_below_an_f32_ulp() {
        // Bin counts with every remainder mod 4, fluxes over six decades (a dim wall's
        // photon next to a caustic's): the four partial sums may round differently from one
        // chain of additions, but only in f64, so the f32 colour is the same.
        let mut rng = Rng::stream(12, 0, 0, Purpose::Photon);
        for n in [3usize, 4, 5, 6, 7, 20, 99, 100] {
            let grid = BinGrid::with_bins(n).unwrap();
            let smits = SmitsBins::new(&grid);
            for _ in 0..500 {
                let spd: Vec<f32> = (0..n)
                    .map(|_| 10f32.powf(6.0 * rng.next_f32() - 3.0))
                    .collect();
                let mut plain = [0.0f64; 3];
                for (w, &v) in smits.weights.iter().zip(&spd) {
                    for c in 0..3 {
                        plain[c] += w[c] as f64 * v as f64;
                    }
                }
                let fast = smits.project(&spd);
                let scale: f64 = spd.iter().map(|&v| v as f64).sum();
                for c in 0..3 {
                    assert!(
                        (fast[c] - plain[c]).abs() <= 1e-13 * scale,
                        "n={n} c={c}: {} vs {}",
                        fast[c],
                        plain[c]
                    );
                }
                assert_eq!(fast.map(|v| v as f32), plain.map(|v| v as f32), "n={n}");
            }
        }
    }
}
