//! Starting charges for the EM when no social-charge detector (Chapter 6) is at hand: a
//! greedy pick among pairwise ray intersections scored by the cone-kernel saliency of
//! Eq 6.1 (the same quantity whose modes are the charges), and frame-to-frame association
//! to build a window's initial charge tracks.

use nalgebra::Vector3;

use super::em::{validate_rays, GazeRay, WindowFrame};
use crate::error::{Error, Result};
use crate::geometry::perspective_distance;

/// Saliency contribution `exp(−‖d‖²/2σ²)` of a ray at `x` (0 behind the eye).
#[inline]
fn kernel(ray: &GazeRay, x: &Vector3<f64>, two_sigma2: f64) -> f64 {
    perspective_distance(&ray.p, &ray.v, x).map_or(0.0, |d| (-d.norm_squared() / two_sigma2).exp())
}

/// Midpoint of the closest points of two rays, when both closest points lie in front of
/// the eyes; `None` for (near) parallel rays.
fn pair_point(a: &GazeRay, b: &GazeRay) -> Option<Vector3<f64>> {
    let w = a.p - b.p;
    let (bb, d, e) = (a.v.dot(&b.v), a.v.dot(&w), b.v.dot(&w));
    let den = 1.0 - bb * bb;
    if den < 1e-9 {
        return None;
    }
    let s = (bb * e - d) / den;
    let t = (e - bb * d) / den;
    if s <= 0.0 || t <= 0.0 {
        return None;
    }
    Some((a.p + a.v * s + b.p + b.v * t) * 0.5)
}

/// `n` starting charges for one frame: candidates are the midpoints of every pair of rays
/// that meet in front of both eyes; the first charge is the candidate of highest saliency
/// `Σₖ exp(−‖dₖ‖²/2σ²)` (Eq 6.1 with bandwidth `σ` radians), each next one maximises the
/// saliency of the rays not yet explained, `Σₖ Πₘ (1 − aₖₘ) exp(…)`. When there are fewer
/// distinct useful candidates than `n`, the best ones are repeated.
///
/// Errors: `n = 0` or `σ ≤ 0` → `InvalidInput`; no two rays meet in front of their eyes →
/// `Degenerate`.
pub fn init_charges(rays: &[GazeRay], n: usize, sigma: f64) -> Result<Vec<Vector3<f64>>> {
    if n == 0 {
        return Err(Error::invalid("n_charges", "zero social charges requested"));
    }
    if !(sigma.is_finite() && sigma > 0.0) {
        return Err(Error::invalid("sigma", "must be finite and > 0"));
    }
    if n > rays.len() {
        // More charges than gazes: the extra charges could only repeat the others.
        return Err(Error::degenerate(format!(
            "{n} social charges cannot be placed with {} gaze rays",
            rays.len()
        )));
    }
    validate_rays("rays", rays)?;
    let mut cands = Vec::new();
    for a in 0..rays.len() {
        for b in a + 1..rays.len() {
            if let Some(x) = pair_point(&rays[a], &rays[b]) {
                cands.push(x);
            }
        }
    }
    if cands.is_empty() {
        return Err(Error::degenerate(
            "no two gaze rays meet in front of their eyes: cannot place a social charge",
        ));
    }
    let two_s2 = 2.0 * sigma * sigma;
    // k[c][r]: kernel of ray r at candidate c.
    let k: Vec<Vec<f64>> = cands
        .iter()
        .map(|x| rays.iter().map(|r| kernel(r, x, two_s2)).collect())
        .collect();
    let mut unexplained = vec![1.0; rays.len()];
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let mut best = (f64::NEG_INFINITY, 0);
        for (c, kc) in k.iter().enumerate() {
            let s: f64 = kc.iter().zip(&unexplained).map(|(a, u)| a * u).sum();
            if s > best.0 {
                best = (s, c);
            }
        }
        out.push(cands[best.1]);
        for (u, a) in unexplained.iter_mut().zip(&k[best.1]) {
            *u *= 1.0 - a;
        }
    }
    Ok(out)
}

/// Permutation `perm` minimising `Σᵢ ‖prev[i] − cur[perm[i]]‖²` (exhaustive up to 7
/// charges, greedy beyond).
pub fn associate(prev: &[Vector3<f64>], cur: &[Vector3<f64>]) -> Vec<usize> {
    let n = prev.len().min(cur.len());
    let cost = |perm: &[usize]| -> f64 {
        perm.iter()
            .enumerate()
            .map(|(i, &j)| (prev[i] - cur[j]).norm_squared())
            .sum()
    };
    if n <= 7 {
        let mut perm: Vec<usize> = (0..n).collect();
        let mut best = (cost(&perm), perm.clone());
        // Heap's algorithm over all permutations.
        let mut c = vec![0usize; n];
        let mut i = 0;
        while i < n {
            if c[i] < i {
                if i % 2 == 0 {
                    perm.swap(0, i);
                } else {
                    perm.swap(c[i], i);
                }
                let v = cost(&perm);
                if v < best.0 {
                    best = (v, perm.clone());
                }
                c[i] += 1;
                i = 0;
            } else {
                c[i] = 0;
                i += 1;
            }
        }
        best.1
    } else {
        let mut used = vec![false; n];
        (0..n)
            .map(|i| {
                let mut b = (f64::INFINITY, 0);
                for j in 0..n {
                    let d = (prev[i] - cur[j]).norm_squared();
                    if !used[j] && d < b.0 {
                        b = (d, j);
                    }
                }
                used[b.1] = true;
                b.1
            })
            .collect()
    }
}

/// Initial charge tracks for a window: [`init_charges`] at every frame, ordered to follow
/// the previous frame ([`associate`]); a frame where no charge can be placed copies its
/// neighbour. Errors with `Degenerate` when no frame of the window can place charges.
pub fn init_window(frames: &[WindowFrame], n: usize, sigma: f64) -> Result<Vec<Vec<Vector3<f64>>>> {
    let mut rows: Vec<Option<Vec<Vector3<f64>>>> = Vec::with_capacity(frames.len());
    for f in frames {
        match init_charges(&f.rays, n, sigma) {
            Ok(r) => rows.push(Some(r)),
            Err(Error::Degenerate(_)) => rows.push(None),
            Err(e) => return Err(e),
        }
    }
    let first = rows
        .iter()
        .position(|r| r.is_some())
        .ok_or_else(|| Error::degenerate("no frame of the window has two gaze rays that meet"))?;
    let mut out: Vec<Vec<Vector3<f64>>> = Vec::with_capacity(frames.len());
    let mut prev: Vec<Vector3<f64>> = rows[first].clone().unwrap_or_default();
    for r in rows {
        let row = match r {
            Some(cur) => {
                let perm = associate(&prev, &cur);
                perm.iter().map(|&j| cur[j]).collect()
            }
            None => prev.clone(),
        };
        prev = row.clone();
        out.push(row);
    }
    Ok(out)
}

/// Initial charge tracks for a window from per-frame candidate positions (e.g. the social
/// charges of Chapter 6, strongest first): a frame with at least `n` candidates keeps its
/// first `n`, ordered to follow the previous frame ([`associate`]); a frame with fewer
/// copies its neighbour. Errors with `Degenerate` when no frame has `n` candidates, and
/// `InvalidInput` for `n = 0` or non-finite candidates.
pub fn init_window_from_candidates(
    candidates: &[Vec<Vector3<f64>>],
    n: usize,
) -> Result<Vec<Vec<Vector3<f64>>>> {
    if n == 0 {
        return Err(Error::invalid("n_charges", "zero social charges requested"));
    }
    for row in candidates {
        for x in row {
            crate::error::ensure_finite("candidates", x.as_slice())?;
        }
    }
    let first = candidates
        .iter()
        .position(|r| r.len() >= n)
        .ok_or_else(|| {
            Error::degenerate(format!("no frame of the window has {n} candidate charges"))
        })?;
    let mut prev: Vec<Vector3<f64>> = candidates[first][..n].to_vec();
    let mut out = Vec::with_capacity(candidates.len());
    for r in candidates {
        let row = if r.len() >= n {
            let cur = &r[..n];
            associate(&prev, cur).iter().map(|&j| cur[j]).collect()
        } else {
            prev.clone()
        };
        prev = row.clone();
        out.push(row);
    }
    Ok(out)
}
