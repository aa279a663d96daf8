//! Temporal association of social charges (Sec 6.1.3): classic mean-shift clustering (flat
//! kernel, Fukunaga–Hostetler) of the charges' membership features (Eq 6.8) over all
//! frames. A cluster is a track; it keeps at most one charge per frame, the one closest to
//! the cluster centre. Because the features describe *who* attends, a group that dissolves
//! and re-forms gets its old track back (Fig 6.3b).

use crate::error::{ensure_finite, Error, Result};
use rayon::prelude::*;
use std::collections::BTreeMap;

/// Settings of [`track_charges`].
#[derive(Debug, Clone, PartialEq)]
pub struct TrackOptions {
    /// Radius of the flat kernel in feature space. Features are unit vectors, so distances
    /// lie in `[0, √2]`; two disjoint groups are `√2` apart, a group of `a` people and the
    /// whole crowd of `n ⊇ a` are `√(2 − 2√(a/n))` apart.
    pub bandwidth: f64,
    /// Iteration cap of each mean-shift climb.
    pub max_iter: usize,
    /// Start one climb per occupied cell of a grid of spacing `bandwidth` (from the cell's
    /// first feature; as scikit-learn's `bin_seeding`) instead of one per feature: far
    /// fewer climbs, same clusters in practice.
    pub bin_seeding: bool,
    /// Frames of a track closer than `max_gap + 1` apart (at most `max_gap` missing frames
    /// between them) belong to the same run; a longer gap starts a new run (the group
    /// dissolved and re-formed: same track id, a new run).
    pub max_gap: usize,
    /// Runs with fewer charges than this are dropped (their charges get track −1): the
    /// short-lived clusters that transitions make (people switching targets one by one
    /// form intermediate groups for a few frames). Tracks left without charges vanish.
    pub min_length: usize,
}

impl Default for TrackOptions {
    fn default() -> Self {
        TrackOptions {
            bandwidth: 0.3,
            max_iter: 300,
            bin_seeding: true,
            max_gap: 5,
            min_length: 10,
        }
    }
}

/// The result of [`track_charges`].
#[derive(Debug, Clone, PartialEq)]
pub struct Tracking {
    /// Track id of every charge (input order), or −1 for a charge that lost its frame's
    /// slot in its track to a charge closer to the track's centre. Ids count from 0 in
    /// order of first appearance.
    pub track: Vec<i64>,
    /// Feature-space centre of every track (`n_tracks` rows of `J`).
    pub centres: Vec<Vec<f64>>,
}

fn dist2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// One flat-kernel mean-shift climb from `start`; returns the mode and how many features
/// lie within the bandwidth of it, or `None` if the window is empty.
fn climb(
    features: &[&[f64]],
    start: &[f64],
    bw: f64,
    max_iter: usize,
) -> Option<(Vec<f64>, usize)> {
    let j = start.len();
    let bw2 = bw * bw;
    let mut m = start.to_vec();
    for _ in 0..max_iter {
        let mut sum = vec![0.0; j];
        let mut count = 0usize;
        for f in features {
            if dist2(f, &m) <= bw2 {
                count += 1;
                sum.iter_mut().zip(f.iter()).for_each(|(s, x)| *s += x);
            }
        }
        if count == 0 {
            return None;
        }
        let next: Vec<f64> = sum.iter().map(|s| s / count as f64).collect();
        let shift = dist2(&next, &m).sqrt();
        m = next;
        if shift < 1e-3 * bw {
            break;
        }
    }
    let count = features.iter().filter(|f| dist2(f, &m) <= bw2).count();
    (count > 0).then_some((m, count))
}

/// Tracks charges across frames from their membership features.
///
/// `features` is `n` rows of `J` values (row `k` is charge `k`'s membership over the `J`
/// people of the whole sequence, Eq 6.8, zero for people absent from its frame);
/// `frames[k]` is the frame of charge `k`.
pub fn track_charges(
    features: &[Vec<f64>],
    frames: &[usize],
    opts: &TrackOptions,
) -> Result<Tracking> {
    if frames.len() != features.len() {
        return Err(Error::invalid(
            "frames",
            format!(
                "has {} entries for {} charges",
                frames.len(),
                features.len()
            ),
        ));
    }
    if !(opts.bandwidth.is_finite() && opts.bandwidth > 0.0) {
        return Err(Error::invalid(
            "bandwidth",
            format!("{} must be finite and > 0", opts.bandwidth),
        ));
    }
    if opts.max_iter == 0 {
        return Err(Error::invalid("max_iter", "must be at least 1"));
    }
    let n = features.len();
    if n == 0 {
        return Ok(Tracking {
            track: vec![],
            centres: vec![],
        });
    }
    let j = features[0].len();
    for (k, f) in features.iter().enumerate() {
        if f.len() != j {
            return Err(Error::invalid(
                "features",
                format!("row {k} has {} values, row 0 has {j}", f.len()),
            ));
        }
        ensure_finite("features", f)?;
    }
    let bw = opts.bandwidth;
    let rows: Vec<&[f64]> = features.iter().map(|f| f.as_slice()).collect();
    let seeds: Vec<Vec<f64>> = if opts.bin_seeding {
        // One seed per occupied cell: the cell's first feature (a real feature, so the
        // climb's first window is never empty).
        let mut bins: BTreeMap<Vec<i64>, usize> = BTreeMap::new();
        for (k, f) in rows.iter().enumerate() {
            bins.entry(f.iter().map(|x| (x / bw).round() as i64).collect())
                .or_insert(k);
        }
        let mut firsts: Vec<usize> = bins.into_values().collect();
        firsts.sort_unstable();
        firsts.into_iter().map(|k| features[k].clone()).collect()
    } else {
        features.to_vec()
    };
    let modes: Vec<Option<(Vec<f64>, usize)>> = seeds
        .par_iter()
        .map(|s| {
            crate::interrupt::check()?;
            Ok(climb(&rows, s, bw, opts.max_iter))
        })
        .collect::<Result<_>>()?;
    // Most populated modes first (ties: seed order); drop modes near a kept one.
    let mut order: Vec<(Vec<f64>, usize, usize)> = modes
        .into_iter()
        .enumerate()
        .filter_map(|(i, m)| m.map(|(c, count)| (c, count, i)))
        .collect();
    order.sort_by(|a, b| b.1.cmp(&a.1).then(a.2.cmp(&b.2)));
    let mut centres: Vec<Vec<f64>> = Vec::new();
    for (c, _, _) in order {
        if centres.iter().all(|k| dist2(k, &c) > bw * bw) {
            centres.push(c);
        }
    }
    if centres.is_empty() {
        return Err(Error::degenerate(
            "mean-shift found no cluster of membership features",
        ));
    }
    // Every charge joins its nearest centre.
    let nearest: Vec<(usize, f64)> = rows
        .par_iter()
        .map(|f| {
            centres
                .iter()
                .enumerate()
                .map(|(c, k)| (c, dist2(f, k)))
                .fold(
                    (0, f64::INFINITY),
                    |best, x| if x.1 < best.1 { x } else { best },
                )
        })
        .collect();
    // At most one charge per cluster and frame: the closest to the centre (ties: first).
    let mut best: BTreeMap<(usize, usize), usize> = BTreeMap::new();
    for (k, &(c, d)) in nearest.iter().enumerate() {
        let slot = best.entry((c, frames[k])).or_insert(k);
        if d < nearest[*slot].1 {
            *slot = k;
        }
    }
    // Ids by first appearance (frame, then charge index).
    let mut first: Vec<Option<(usize, usize)>> = vec![None; centres.len()];
    for (&(c, frame), &k) in &best {
        let key = (frame, k);
        if first[c].map_or(true, |f| key < f) {
            first[c] = Some(key);
        }
    }
    let mut used: Vec<(usize, usize, usize)> = first
        .iter()
        .enumerate()
        .filter_map(|(c, f)| f.map(|(frame, k)| (frame, k, c)))
        .collect();
    used.sort();
    let mut id_of = vec![-1i64; centres.len()];
    for (id, &(_, _, c)) in used.iter().enumerate() {
        id_of[c] = id as i64;
    }
    let mut track = vec![-1i64; n];
    for (&(c, _), &k) in &best {
        track[k] = id_of[c];
    }
    let centres: Vec<Vec<f64>> = used.iter().map(|&(_, _, c)| centres[c].clone()).collect();
    Ok(drop_short_runs(track, centres, frames, opts))
}

/// Applies [`TrackOptions::max_gap`] and [`TrackOptions::min_length`]: drops the charges of
/// short runs, then the tracks left empty, and renumbers the rest by first appearance.
fn drop_short_runs(
    mut track: Vec<i64>,
    centres: Vec<Vec<f64>>,
    frames: &[usize],
    opts: &TrackOptions,
) -> Tracking {
    let mut by_track: Vec<Vec<usize>> = vec![Vec::new(); centres.len()];
    for (k, &t) in track.iter().enumerate() {
        if let Ok(t) = usize::try_from(t) {
            by_track[t].push(k);
        }
    }
    for ks in by_track.iter_mut() {
        ks.sort_by_key(|&k| frames[k]);
        let mut start = 0;
        for e in 1..=ks.len() {
            let split = e == ks.len() || frames[ks[e]] - frames[ks[e - 1]] > opts.max_gap + 1;
            if split {
                if e - start < opts.min_length {
                    ks[start..e].iter().for_each(|&k| track[k] = -1);
                }
                start = e;
            }
        }
    }
    // Renumber the surviving tracks by first appearance (frame, then charge index).
    let mut first: Vec<Option<(usize, usize)>> = vec![None; centres.len()];
    for (k, &t) in track.iter().enumerate() {
        if let Ok(t) = usize::try_from(t) {
            let key = (frames[k], k);
            if first[t].map_or(true, |f| key < f) {
                first[t] = Some(key);
            }
        }
    }
    let mut order: Vec<(usize, usize, usize)> = first
        .iter()
        .enumerate()
        .filter_map(|(t, f)| f.map(|(frame, k)| (frame, k, t)))
        .collect();
    order.sort();
    let mut new_id = vec![-1i64; centres.len()];
    for (id, &(_, _, t)) in order.iter().enumerate() {
        new_id[t] = id as i64;
    }
    for t in track.iter_mut() {
        if let Ok(old) = usize::try_from(*t) {
            *t = new_id[old];
        }
    }
    let centres = order.iter().map(|&(_, _, t)| centres[t].clone()).collect();
    Tracking { track, centres }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn unit(v: &[f64]) -> Vec<f64> {
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        v.iter().map(|x| x / n).collect()
    }

    #[test]
    fn groups_split_merge_and_reappear_with_stable_ids() {
        // Frames 0–9: groups A = {0,1,2}, B = {3,4}; 10–19: all together; 20–29: A, B again.
        // A noisy duplicate of A appears in frame 5.
        let a = unit(&[1.0, 1.0, 1.0, 0.0, 0.0]);
        let b = unit(&[0.0, 0.0, 0.0, 1.0, 1.0]);
        let all = unit(&[1.0; 5]);
        let mut feats = Vec::new();
        let mut frames = Vec::new();
        for t in 0..30usize {
            let wobble = 0.02 * ((t as f64) * 1.7).sin();
            let jitter = |v: &Vec<f64>| {
                unit(
                    &v.iter()
                        .enumerate()
                        .map(|(i, x)| x + wobble * (i as f64 - 2.0) * 0.1)
                        .collect::<Vec<_>>(),
                )
            };
            if (10..20).contains(&t) {
                feats.push(jitter(&all));
                frames.push(t);
            } else {
                feats.push(jitter(&a));
                frames.push(t);
                feats.push(jitter(&b));
                frames.push(t);
            }
            if t == 5 {
                feats.push(unit(&[1.0, 1.2, 0.8, 0.05, 0.0]));
                frames.push(t);
            }
        }
        let tr = track_charges(&feats, &frames, &TrackOptions::default()).unwrap();
        assert_eq!(tr.centres.len(), 3);
        // Ids by first appearance: A is 0, B is 1 (frame 0), all-together is 2.
        for (k, &t) in frames.iter().enumerate() {
            let want = if feats[k] == unit(&[1.0, 1.2, 0.8, 0.05, 0.0]) {
                -1
            } else if (10..20).contains(&t) {
                2
            } else if feats[k][0] > 0.3 {
                0
            } else {
                1
            };
            assert_eq!(tr.track[k], want, "charge {k} frame {t}");
        }
        // Without bin seeding, same tracks.
        let o = TrackOptions {
            bin_seeding: false,
            ..Default::default()
        };
        assert_eq!(track_charges(&feats, &frames, &o).unwrap().track, tr.track);
    }

    #[test]
    fn empty_and_bad_input() {
        let tr = track_charges(&[], &[], &TrackOptions::default()).unwrap();
        assert!(tr.track.is_empty());
        assert!(track_charges(&[vec![1.0]], &[], &TrackOptions::default()).is_err());
        assert!(track_charges(
            &[vec![1.0], vec![1.0, 0.0]],
            &[0, 1],
            &TrackOptions::default()
        )
        .is_err());
        assert!(track_charges(&[vec![f64::NAN]], &[0], &TrackOptions::default()).is_err());
        let o = TrackOptions {
            bandwidth: 0.0,
            ..Default::default()
        };
        assert!(track_charges(&[vec![1.0]], &[0], &o).is_err());
    }
}
