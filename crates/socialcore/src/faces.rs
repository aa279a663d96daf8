//! 3D faces from the face detections of several calibrated cameras (thesis Sec 3.2.2).
//!
//! - [`associate`]: which detections of one time instant are the same face (Eq 3.2).
//!   Wearers' faces are anchored to their own head camera (the projection of its centre
//!   into the other views); the remaining detections are split by sequential RANSAC over
//!   pairs of detections from different cameras: triangulate the landmarks of the pair,
//!   keep the hypothesis if it reprojects and has a human interocular distance, add the
//!   best reprojecting detection of every other camera, keep the largest group, remove it,
//!   repeat. The hypotheses are enumerated exhaustively (deterministic; a frame has few
//!   detections), and no two detections of one camera ever join one face. A tracked face
//!   (an anchor without a camera) keeps only the detections that make one face with a
//!   face's proportions.
//! - [`triangulate_faces`]: Eq 3.3, every landmark of every face by DLT then
//!   Levenberg–Marquardt, with its standard deviation from the Gauss–Newton covariance.
//! - [`refine_track`]: Eq 3.4 over one face track: reprojection + λ × first differences,
//!   Gauss–Newton on a block-tridiagonal (banded) system per landmark.
//! - [`gaze_from_landmarks`]: the primary gaze ray of a face: origin between the eyes,
//!   direction normal to the plane of the eyes and mouth corners, pointing forward.
//!
//! Landmark order: image-left eye, image-right eye, nose, image-left and image-right mouth
//! corner of a face seen from the front (so the person's right eye comes first).

use crate::error::{Error, Result};
use crate::geometry::{refine_point, triangulate_dlt, Camera, LmOptions};
use nalgebra::{Matrix3, Vector2, Vector3};
use rayon::prelude::*;

/// Landmarks per face.
pub const N_LANDMARKS: usize = 5;

/// The 3D landmarks of one face.
pub type Landmarks3 = [Vector3<f64>; N_LANDMARKS];

/// One face detection: the camera slot it was seen in (an index into the cameras passed
/// alongside), its landmarks and its size (box side, pixels).
#[derive(Debug, Clone)]
pub struct Detection {
    pub slot: usize,
    pub landmarks: [Vector2<f64>; N_LANDMARKS],
    pub size: f64,
}

/// A known person at one instant: a wearer's head camera (its centre and the slot of its
/// own view, never associated with its own face) or a tracked face (its predicted eye
/// midpoint, `slot` = `usize::MAX`). `gate`: the largest distance (metres, at the anchor's
/// depth) between the anchor's projection and a detection's eye midpoint.
#[derive(Debug, Clone, Copy)]
pub struct Anchor {
    pub centre: Vector3<f64>,
    pub slot: usize,
    pub gate: f64,
}

/// Options of [`associate`].
#[derive(Debug, Clone, Copy)]
pub struct AssociationOptions {
    /// Reprojection threshold as a fraction of the detection's size.
    pub rel_threshold: f64,
    /// Smallest reprojection threshold, pixels.
    pub min_threshold: f64,
    /// Plausible interocular distances, metres.
    pub interocular: (f64, f64),
    /// Plausible eyes-to-mouth distances (eye midpoint to mouth-corner midpoint) as a
    /// multiple of the interocular distance.
    pub shape: (f64, f64),
}

impl Default for AssociationOptions {
    fn default() -> Self {
        AssociationOptions {
            rel_threshold: 0.1,
            min_threshold: 1.5,
            interocular: (0.045, 0.085),
            shape: (0.5, 1.6),
        }
    }
}

/// Groups of detections of one instant: `label[i]` is the group of detection `i` (`None`
/// = in no group) and `anchor[g]` the anchor a group belongs to (`None` for RANSAC groups).
#[derive(Debug, Clone, Default)]
pub struct Association {
    pub label: Vec<Option<usize>>,
    pub anchor: Vec<Option<usize>>,
}

fn check_slots(n_cams: usize, dets: &[Detection], anchors: &[Anchor]) -> Result<()> {
    if let Some(d) = dets.iter().find(|d| d.slot >= n_cams) {
        return Err(Error::invalid(
            "slot",
            format!("camera slot {} out of range (0..{n_cams})", d.slot),
        ));
    }
    if let Some(a) = anchors
        .iter()
        .find(|a| a.slot >= n_cams && a.slot != usize::MAX)
    {
        return Err(Error::invalid(
            "anchor_slot",
            format!("camera slot {} out of range (0..{n_cams})", a.slot),
        ));
    }
    for d in dets {
        let vals: Vec<f64> = d
            .landmarks
            .iter()
            .flat_map(|p| [p.x, p.y])
            .chain([d.size])
            .collect();
        crate::error::ensure_finite("landmarks", &vals)?;
        if d.size <= 0.0 {
            return Err(Error::invalid("size", "face sizes must be > 0"));
        }
    }
    Ok(())
}

fn eye_mid(d: &Detection) -> Vector2<f64> {
    (d.landmarks[0] + d.landmarks[1]) * 0.5
}

/// Triangulates the landmarks seen in `views` (DLT + LM); `None` if a landmark fails.
fn triangulate_landmarks(
    cams: &[Camera],
    views: &[&Detection],
    opts: &LmOptions,
) -> Option<[Vector3<f64>; N_LANDMARKS]> {
    let mut out = [Vector3::zeros(); N_LANDMARKS];
    for (p, x) in out.iter_mut().enumerate() {
        let obs: Vec<(&Camera, Vector2<f64>)> = views
            .iter()
            .map(|d| (&cams[d.slot], d.landmarks[p]))
            .collect();
        let x0 = triangulate_dlt(&obs).ok()?;
        *x = refine_point(x0, &obs, opts).0;
    }
    Some(out)
}

/// RMS reprojection error (pixels) of a detection against 3D landmarks; infinite when a
/// landmark is behind the camera.
fn face_rms(cam: &Camera, d: &Detection, x: &[Vector3<f64>; N_LANDMARKS]) -> f64 {
    let mut s = 0.0;
    for (xp, lp) in x.iter().zip(&d.landmarks) {
        let (u, z) = cam.project(xp);
        if z <= 0.0 {
            return f64::INFINITY;
        }
        s += (u - lp).norm_squared();
    }
    (s / N_LANDMARKS as f64).sqrt()
}

/// Eyes-to-mouth distance (eye midpoint to mouth-corner midpoint) over the interocular
/// distance.
fn shape_ratio(x: &[Vector3<f64>; N_LANDMARKS]) -> f64 {
    let down = (x[3] + x[4] - x[0] - x[1]) * 0.5;
    down.norm() / (x[1] - x[0]).norm()
}

/// Whether triangulated landmarks look like a human face seen by `cams`: a plausible
/// interocular distance, eyes-to-mouth about as long as the eyes are apart and roughly
/// perpendicular to them, and the face turned towards every camera that saw it (wrong
/// pairs of detections from two views triangulate to stretched or skewed faces).
fn plausible(x: &[Vector3<f64>; N_LANDMARKS], o: &AssociationOptions, cams: &[&Camera]) -> bool {
    let across = x[1] - x[0];
    let io = across.norm();
    if io < o.interocular.0 || io > o.interocular.1 {
        return false;
    }
    let down = (x[3] + x[4] - x[0] - x[1]) * 0.5;
    if !(o.shape.0..=o.shape.1).contains(&shape_ratio(x))
        || across.dot(&down).abs() > 0.4 * io * down.norm()
    {
        return false;
    }
    let fwd = down.cross(&across);
    let mid = (x[0] + x[1]) * 0.5;
    cams.iter().all(|c| fwd.dot(&(c.c - mid)) > 0.0)
}

fn threshold(d: &Detection, o: &AssociationOptions) -> f64 {
    (o.rel_threshold * d.size).max(o.min_threshold)
}

/// How much wider than RANSAC's reprojection test a track's own test is: a track knows
/// where its face is, the test keeps other people's faces and phantoms out, not noisy
/// views (with RANSAC's own test, views of synthetic faces with 1 px landmark noise were
/// dropped and the rigid refinement's tests no longer held; with 3× a track still loses
/// another person's face 9 cm beside its own, and association without anchors on
/// rendered circles 1–3 is 0.99–1.00, against 0.79–0.87 with no test).
const TRACK_SLACK: f64 = 3.0;

/// The members of a tracked group (indices into `dets`, ≥ 2 cameras) that stay: all of
/// them when their triangulation reprojects within [`TRACK_SLACK`] × the RANSAC test with
/// a face's proportions; else the largest set a pair of them with a face's proportions
/// reprojects so (ties: the smaller summed error); empty when no pair passes.
fn tracked_consensus(
    cams: &[Camera],
    dets: &[Detection],
    members: &[usize],
    o: &AssociationOptions,
    lm: &LmOptions,
) -> Vec<usize> {
    let shaped = |x: &Landmarks3| (o.shape.0..=o.shape.1).contains(&shape_ratio(x));
    let within = |x: &Landmarks3| -> (Vec<usize>, f64) {
        let mut inl = Vec::new();
        let mut err = 0.0;
        for &k in members {
            let r = face_rms(&cams[dets[k].slot], &dets[k], x);
            if r <= TRACK_SLACK * threshold(&dets[k], o) {
                inl.push(k);
                err += r;
            }
        }
        (inl, err)
    };
    let all: Vec<&Detection> = members.iter().map(|&i| &dets[i]).collect();
    if let Some(x) = triangulate_landmarks(cams, &all, lm) {
        if shaped(&x) && within(&x).0.len() == members.len() {
            return members.to_vec();
        }
    }
    let mut best: (Vec<usize>, f64) = (Vec::new(), f64::INFINITY);
    for (ai, &i) in members.iter().enumerate() {
        for &j in &members[ai + 1..] {
            let Some(x) = triangulate_landmarks(cams, &[&dets[i], &dets[j]], lm) else {
                continue;
            };
            if !shaped(&x) {
                continue;
            }
            let (inl, err) = within(&x);
            if !(inl.contains(&i) && inl.contains(&j)) {
                continue;
            }
            if inl.len() > best.0.len() || (inl.len() == best.0.len() && err < best.1) {
                best = (inl, err);
            }
        }
    }
    best.0
}

/// Eq 3.2 for one instant (see the module docs). `cams` are the views of that instant.
pub fn associate(
    cams: &[Camera],
    dets: &[Detection],
    anchors: &[Anchor],
    o: &AssociationOptions,
) -> Result<Association> {
    check_slots(cams.len(), dets, anchors)?;
    let n = dets.len();
    let mut label: Vec<Option<usize>> = vec![None; n];
    let mut group_anchor: Vec<Option<usize>> = Vec::new();
    // (a) anchors: greedy over (anchor, detection) pairs by metric distance
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (a, an) in anchors.iter().enumerate() {
        for (i, d) in dets.iter().enumerate() {
            if d.slot == an.slot {
                continue;
            }
            let cam = &cams[d.slot];
            let (u, z) = cam.project(&an.centre);
            if z <= 0.0 {
                continue;
            }
            let metres = (u - eye_mid(d)).norm() * z / cam.k[(0, 0)];
            if metres <= an.gate {
                pairs.push((metres, a, i));
            }
        }
    }
    // head cameras first: a wearer's own camera says who the face is, a tracked face only
    // where it was; a track claiming by distance alone took the faces of wearers it passed
    // in front of (a 2-view track of two people's faces, placed on one camera's line of
    // sight through a wearer's face, is nearer to it than the wearer's camera centre)
    let tracked = |a: usize| anchors[a].slot == usize::MAX;
    pairs.sort_by(|x, y| tracked(x.1).cmp(&tracked(y.1)).then(x.0.total_cmp(&y.0)));
    let mut anchor_group: Vec<Option<usize>> = vec![None; anchors.len()];
    let mut used_slot: Vec<Vec<usize>> = vec![Vec::new(); anchors.len()];
    for &(_, a, i) in &pairs {
        if label[i].is_some() || used_slot[a].contains(&dets[i].slot) {
            continue;
        }
        let g = *anchor_group[a].get_or_insert_with(|| {
            group_anchor.push(Some(a));
            group_anchor.len() - 1
        });
        label[i] = Some(g);
        used_slot[a].push(dets[i].slot);
    }
    // a tracked face seen by several cameras must still be one face with a face's
    // proportions: two people each seen by one camera, whose lines of sight cross, make a
    // phantom face that a track would otherwise keep claiming from both cameras once RANSAC
    // let it through (a rendered circle with SfM poses: eyes-to-mouth 0.45–0.48 × the
    // interocular distance for 10 instants, real faces 0.85–1.2), and a track claiming by
    // distance takes other people's faces. So the track keeps the largest set of its
    // detections that a pair of them with a face's proportions reprojects (within
    // `TRACK_SLACK` × the RANSAC test); the others sit this instant out (given to RANSAC,
    // the detections of a dropped phantom made a one-instant phantom of two other people).
    // Only the proportions: with the interocular and turned-to tests too, real tracked
    // faces were dropped (1.2 % of the face-instants of 24 rendered circles, and wrong
    // pairs on two).
    let lm = LmOptions {
        max_iterations: 20,
        rel_tol: 1e-10,
    };
    let mut blocked = vec![false; n];
    let mut dropped = vec![false; group_anchor.len()];
    for (a, g) in anchor_group.iter().enumerate() {
        let Some(g) = *g else { continue };
        if !tracked(a) || used_slot[a].len() < 2 {
            continue;
        }
        let members: Vec<usize> = (0..n).filter(|&i| label[i] == Some(g)).collect();
        let keep = tracked_consensus(cams, dets, &members, o, &lm);
        for &i in &members {
            if !keep.contains(&i) {
                label[i] = None;
                blocked[i] = true;
            }
        }
        dropped[g] = keep.is_empty();
    }
    if dropped.iter().any(|&d| d) {
        let mut new_id = vec![None; group_anchor.len()];
        let mut kept = Vec::new();
        for (g, &d) in dropped.iter().enumerate() {
            if !d {
                new_id[g] = Some(kept.len());
                kept.push(group_anchor[g]);
            }
        }
        for l in label.iter_mut() {
            *l = l.and_then(|g| new_id[g]);
        }
        group_anchor = kept;
    }
    // (b) sequential RANSAC over pairs of the remaining detections
    loop {
        crate::interrupt::check()?;
        let free: Vec<usize> = (0..n)
            .filter(|&i| label[i].is_none() && !blocked[i])
            .collect();
        let mut best: Option<(usize, f64, Vec<usize>)> = None;
        for (ai, &i) in free.iter().enumerate() {
            for &j in &free[ai + 1..] {
                if dets[i].slot == dets[j].slot {
                    continue;
                }
                let pair = [&dets[i], &dets[j]];
                let Some(x) = triangulate_landmarks(cams, &pair, &lm) else {
                    continue;
                };
                if !plausible(&x, o, &[&cams[dets[i].slot], &cams[dets[j].slot]]) {
                    continue;
                }
                let ri = face_rms(&cams[dets[i].slot], &dets[i], &x);
                let rj = face_rms(&cams[dets[j].slot], &dets[j], &x);
                if ri > threshold(&dets[i], o) || rj > threshold(&dets[j], o) {
                    continue;
                }
                // the best reprojecting free detection of every other camera
                let mut members = vec![i, j];
                let mut err = ri + rj;
                let mut per_slot: Vec<(usize, f64, usize)> = Vec::new();
                for &k in &free {
                    if k == i || k == j {
                        continue;
                    }
                    let s = dets[k].slot;
                    if s == dets[i].slot || s == dets[j].slot {
                        continue;
                    }
                    let r = face_rms(&cams[s], &dets[k], &x);
                    if r > threshold(&dets[k], o) {
                        continue;
                    }
                    match per_slot.iter_mut().find(|e| e.0 == s) {
                        Some(e) if r < e.1 => *e = (s, r, k),
                        Some(_) => {}
                        None => per_slot.push((s, r, k)),
                    }
                }
                for (_, r, k) in per_slot {
                    members.push(k);
                    err += r;
                }
                let better = match &best {
                    None => true,
                    Some((m, e, _)) => members.len() > *m || (members.len() == *m && err < *e),
                };
                if better {
                    best = Some((members.len(), err, members));
                }
            }
        }
        let Some((_, _, members)) = best else { break };
        group_anchor.push(None);
        let g = group_anchor.len() - 1;
        for k in members {
            label[k] = Some(g);
        }
    }
    Ok(Association {
        label,
        anchor: group_anchor,
    })
}

/// One triangulated face: landmarks, their standard deviations (metres, the root of the
/// mean variance per axis), the RMS reprojection error and the number of views.
#[derive(Debug, Clone, Copy)]
pub struct Face3 {
    pub x: [Vector3<f64>; N_LANDMARKS],
    pub std: [f64; N_LANDMARKS],
    pub rms: f64,
    pub views: usize,
}

/// Gauss–Newton normal matrix `Σ Jᵀ J / σ²` of one point seen in `obs` (pixel σ each).
fn normal_matrix(x: &Vector3<f64>, obs: &[(&Camera, Vector2<f64>, f64)]) -> Matrix3<f64> {
    let mut jtj = Matrix3::zeros();
    for (c, _, sigma) in obs {
        let kr = c.k * c.r;
        let h = kr * (x - c.c);
        let iz = 1.0 / h.z;
        let ju = (kr.row(0) - h.x * iz * kr.row(2)) * iz;
        let jv = (kr.row(1) - h.y * iz * kr.row(2)) * iz;
        jtj += (ju.transpose() * ju + jv.transpose() * jv) / (sigma * sigma);
    }
    jtj
}

fn std_of(cov_inv: &Matrix3<f64>) -> f64 {
    match cov_inv.try_inverse() {
        Some(c) if c.trace() > 0.0 => (c.trace() / 3.0).sqrt(),
        _ => f64::INFINITY,
    }
}

/// Eq 3.3 for one group of detections (at least two, from different cameras);
/// `sigma[i]` is the landmark noise (pixels) of `views[i]`.
pub fn triangulate_face(cams: &[Camera], views: &[&Detection], sigma: &[f64]) -> Result<Face3> {
    if views.len() < 2 {
        return Err(Error::degenerate(format!(
            "a face needs at least 2 views to be triangulated, it has {}",
            views.len()
        )));
    }
    let lm = LmOptions::default();
    let x = triangulate_landmarks(cams, views, &lm)
        .ok_or_else(|| Error::degenerate("the landmarks of a face could not be triangulated"))?;
    let mut std = [0.0; N_LANDMARKS];
    let mut s2 = 0.0;
    for p in 0..N_LANDMARKS {
        let obs: Vec<(&Camera, Vector2<f64>, f64)> = views
            .iter()
            .zip(sigma)
            .map(|(d, &s)| (&cams[d.slot], d.landmarks[p], s))
            .collect();
        std[p] = std_of(&normal_matrix(&x[p], &obs));
    }
    for d in views {
        let r = face_rms(&cams[d.slot], d, &x);
        s2 += r * r;
    }
    Ok(Face3 {
        x,
        std,
        rms: (s2 / views.len() as f64).sqrt(),
        views: views.len(),
    })
}

/// [`triangulate_face`] for every group `label` of `dets` (`n_groups` groups), in
/// parallel; groups with fewer than two views or failing triangulation give `None`.
pub fn triangulate_faces(
    cams: &[Camera],
    dets: &[Detection],
    sigma: &[f64],
    label: &[Option<usize>],
    n_groups: usize,
) -> Result<Vec<Option<Face3>>> {
    check_slots(cams.len(), dets, &[])?;
    if sigma.len() != dets.len() || label.len() != dets.len() {
        return Err(Error::invalid(
            "sigma",
            "need one sigma and one label per detection",
        ));
    }
    if sigma.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return Err(Error::invalid(
            "sigma",
            "landmark noise must be finite and > 0",
        ));
    }
    if label.iter().flatten().any(|&g| g >= n_groups) {
        return Err(Error::invalid("group", format!("a group id ≥ {n_groups}")));
    }
    crate::error::ensure_alloc("group", &[n_groups], 24)?;
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); n_groups];
    for (i, l) in label.iter().enumerate() {
        if let Some(g) = *l {
            if g >= n_groups {
                return Err(Error::invalid(
                    "group",
                    format!("group {g} out of range (0..{n_groups})"),
                ));
            }
            if members[g].iter().any(|&k| dets[k].slot == dets[i].slot) {
                return Err(Error::invalid(
                    "group",
                    format!(
                        "two detections of camera slot {} in group {g}",
                        dets[i].slot
                    ),
                ));
            }
            members[g].push(i);
        }
    }
    Ok(members
        .par_iter()
        .map(|m| {
            if m.len() < 2 || crate::interrupt::check().is_err() {
                return None;
            }
            let views: Vec<&Detection> = m.iter().map(|&i| &dets[i]).collect();
            let s: Vec<f64> = m.iter().map(|&i| sigma[i]).collect();
            triangulate_face(cams, &views, &s).ok()
        })
        .collect())
}

/// Eq 3.4 over one track of `t_len` instants: `obs` are `(instant, camera, landmarks,
/// sigma)`; `x0` the initial landmarks per instant (from Eq 3.3 or interpolated; every
/// instant needs one). The temporal term penalises the change of the face between
/// consecutive instants, split into the motion of its centre (the landmarks' mean), weighed
/// by `lam_centre`, and the change of its configuration about that centre (a turn of the
/// head), weighed by `lam_shape` (1/m², the cost being in units of σ): `Σ_t dᵀ W d`,
/// `d = X(t+1) − X(t)` over all landmarks, `W = lam_centre·A + lam_shape·(I − A)` with `A`
/// the averaging projector. `lam_centre == lam_shape` is the thesis' `λ Σ ‖X(t+1) − X(t)‖²`.
/// Returns the refined landmarks and their standard deviations (metres, from the diagonal
/// blocks of the normal matrix, so slightly pessimistic).
pub fn refine_track(
    cams: &[Camera],
    obs: &[(usize, usize, [Vector2<f64>; N_LANDMARKS], f64)],
    x0: &[[Vector3<f64>; N_LANDMARKS]],
    lam_centre: f64,
    lam_shape: f64,
    iterations: usize,
) -> Result<(Vec<Landmarks3>, Vec<[f64; N_LANDMARKS]>)> {
    let t_len = x0.len();
    if t_len == 0 {
        return Err(Error::invalid("x0", "an empty track"));
    }
    if !(lam_centre.is_finite() && lam_centre >= 0.0) {
        return Err(Error::invalid("lam", "must be finite and ≥ 0"));
    }
    if !(lam_shape.is_finite() && lam_shape >= 0.0) {
        return Err(Error::invalid("lam_shape", "must be finite and ≥ 0"));
    }
    for &(t, s, _, sigma) in obs {
        if t >= t_len || s >= cams.len() {
            return Err(Error::invalid(
                "step",
                "an observation's instant or camera is out of range",
            ));
        }
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(Error::invalid(
                "sigma",
                "landmark noise must be finite and > 0",
            ));
        }
    }
    let flat: Vec<f64> = x0
        .iter()
        .flat_map(|f| f.iter().flat_map(|v| [v.x, v.y, v.z]))
        .collect();
    crate::error::ensure_finite("x0", &flat)?;
    // W = lam_centre · A + lam_shape · (I − A), A = (J/5) ⊗ I₃
    let mut w = Mat15::identity() * lam_shape;
    let np = N_LANDMARKS as f64;
    for p in 0..N_LANDMARKS {
        for q in 0..N_LANDMARKS {
            for j in 0..3 {
                w[(3 * p + j, 3 * q + j)] += (lam_centre - lam_shape) / np;
            }
        }
    }
    let mut x: Vec<Vec15> = x0
        .iter()
        .map(|f| Vec15::from_fn(|i, _| f[i / 3][i % 3]))
        .collect();
    // the shape part of W, for the robust (Cauchy) weights of the turns
    let mut ws = Mat15::identity() * lam_shape;
    for p in 0..N_LANDMARKS {
        for q in 0..N_LANDMARKS {
            for j in 0..3 {
                ws[(3 * p + j, 3 * q + j)] -= lam_shape / np;
            }
        }
    }
    let wc = w - ws;
    let mut diag = vec![Mat15::zeros(); t_len];
    for it in 0..iterations.max(1) {
        crate::interrupt::check()?;
        // IRLS from the second iteration on (the first, fully smoothed solution is the
        // start): a turn far beyond the expected rate is let through (Cauchy weight
        // 1 / (1 + r²/c²)) instead of being smoothed away
        let edges: Vec<Mat15> = (0..t_len.saturating_sub(1))
            .map(|t| {
                let d = x[t + 1] - x[t];
                let r2 = d.dot(&(ws * d));
                let wt = if it == 0 {
                    1.0
                } else {
                    1.0 / (1.0 + r2 / ROBUST_C2)
                };
                wc + ws * wt
            })
            .collect();
        let mut a = vec![Mat15::zeros(); t_len];
        let mut b = vec![Vec15::zeros(); t_len];
        for &(t, s, ref lms, sigma) in obs {
            let c = &cams[s];
            let kr = c.k * c.r;
            for p in 0..N_LANDMARKS {
                let xp = Vector3::new(x[t][3 * p], x[t][3 * p + 1], x[t][3 * p + 2]);
                let h = kr * (xp - c.c);
                if h.z <= 0.0 {
                    continue;
                }
                let iz = 1.0 / h.z;
                let (pu, pv) = (h.x * iz, h.y * iz);
                let ju = (kr.row(0) - pu * kr.row(2)) * iz / sigma;
                let jv = (kr.row(1) - pv * kr.row(2)) * iz / sigma;
                let (ru, rv) = ((pu - lms[p].x) / sigma, (pv - lms[p].y) / sigma);
                let jtj = ju.transpose() * ju + jv.transpose() * jv;
                let g = ju.transpose() * ru + jv.transpose() * rv;
                for i in 0..3 {
                    b[t][3 * p + i] -= g[i];
                    for j in 0..3 {
                        a[t][(3 * p + i, 3 * p + j)] += jtj[(i, j)];
                    }
                }
            }
        }
        for t in 0..t_len {
            a[t] += Mat15::identity() * 1e-12;
            if t > 0 {
                a[t] += edges[t - 1];
                b[t] -= edges[t - 1] * (x[t] - x[t - 1]);
            }
            if t + 1 < t_len {
                a[t] += edges[t];
                b[t] -= edges[t] * (x[t] - x[t + 1]);
            }
        }
        diag.clone_from(&a);
        let dx = solve_block_tridiagonal(&a, &edges, &b)?;
        let mut big = 0.0f64;
        for t in 0..t_len {
            x[t] += dx[t];
            big = big.max(dx[t].amax());
        }
        if big < 1e-9 {
            break;
        }
    }
    let mut out = Vec::with_capacity(t_len);
    let mut std = Vec::with_capacity(t_len);
    for t in 0..t_len {
        out.push(std::array::from_fn(|p| {
            Vector3::new(x[t][3 * p], x[t][3 * p + 1], x[t][3 * p + 2])
        }));
        std.push(std::array::from_fn(|p| {
            std_of(&diag[t].fixed_view::<3, 3>(3 * p, 3 * p).into_owned())
        }));
    }
    Ok((out, std))
}

type Mat15 = nalgebra::SMatrix<f64, 15, 15>;
type Vec15 = nalgebra::SVector<f64, 15>;

/// Cauchy scale (squared) of the robust temporal term. A turn at the expected rate gives
/// `r² ≈ 5` (five landmarks, each moved by about one expected step), so turns beyond about
/// three times the expected rate are treated as real turns.
const ROBUST_C2: f64 = 45.0;

/// Solves the symmetric block-tridiagonal system with diagonal blocks `a` and off-diagonal
/// blocks `−w[t]` between instants `t` and `t + 1` (block Thomas algorithm).
fn solve_block_tridiagonal(a: &[Mat15], w: &[Mat15], b: &[Vec15]) -> Result<Vec<Vec15>> {
    let n = a.len();
    let mut c_prime: Vec<Mat15> = Vec::with_capacity(n);
    let mut d_prime: Vec<Vec15> = Vec::with_capacity(n);
    for t in 0..n {
        let (m, rhs) = if t == 0 {
            (a[0], b[0])
        } else {
            (
                a[t] + w[t - 1] * c_prime[t - 1],
                b[t] + w[t - 1] * d_prime[t - 1],
            )
        };
        let inv = m.try_inverse().ok_or_else(|| {
            Error::degenerate("the track's normal equations are singular (too few views)")
        })?;
        c_prime.push(if t + 1 < n {
            -(inv * w[t])
        } else {
            Mat15::zeros()
        });
        d_prime.push(inv * rhs);
    }
    let mut x = vec![Vec15::zeros(); n];
    x[n - 1] = d_prime[n - 1];
    for t in (0..n - 1).rev() {
        x[t] = d_prime[t] - c_prime[t] * x[t + 1];
    }
    Ok(x)
}

/// The primary gaze ray of a face: origin between the eyes, unit direction normal to the
/// least-squares plane of the eyes and mouth corners, signed forward (the person's right
/// eye comes first, so forward is `(mouth − eyes) × (eye₂ − eye₁)`), and the direction's
/// angular standard deviation (radians) from the landmark standard deviations.
pub fn gaze_from_landmarks(
    x: &[Vector3<f64>; N_LANDMARKS],
    std: &[f64; N_LANDMARKS],
) -> Result<(Vector3<f64>, Vector3<f64>, f64)> {
    let ext = [x[0], x[1], x[3], x[4]];
    let mean = ext.iter().sum::<Vector3<f64>>() / 4.0;
    let mut m = Matrix3::zeros();
    for e in &ext {
        let d = e - mean;
        m += d * d.transpose();
    }
    let eig = m.symmetric_eigen();
    let k = eig.eigenvalues.imin();
    let mut n: Vector3<f64> = eig.eigenvectors.column(k).into_owned();
    let across = x[1] - x[0];
    let down = (x[3] + x[4] - x[0] - x[1]) * 0.5;
    let fwd = down.cross(&across);
    if fwd.norm() < 1e-12 || !n.iter().all(|v| v.is_finite()) {
        return Err(Error::degenerate("the face landmarks are collinear"));
    }
    if n.dot(&fwd) < 0.0 {
        n = -n;
    }
    let p = (x[0] + x[1]) * 0.5;
    let s_across = (std[0].powi(2) + std[1].powi(2)).sqrt() / across.norm();
    let s_down = ((std[0].powi(2) + std[1].powi(2) + std[3].powi(2) + std[4].powi(2)) / 4.0).sqrt()
        / down.norm();
    Ok((p, n.normalize(), (s_across.powi(2) + s_down.powi(2)).sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(c: Vector3<f64>, look: Vector3<f64>, i: usize) -> Camera {
        let z = (look - c).normalize();
        let x = z.cross(&Vector3::z()).normalize(); // image x right, y down
        let y = z.cross(&x);
        let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
        let k = Matrix3::new(800.0, 0.0, 640.0, 0.0, 800.0, 480.0, 0.0, 0.0, 1.0);
        Camera::new(k, r, c, i).unwrap()
    }

    /// A face at `centre` looking along `fwd` (horizontal): landmarks in order.
    fn face(centre: Vector3<f64>, fwd: Vector3<f64>) -> [Vector3<f64>; 5] {
        let left = Vector3::z().cross(&fwd).normalize(); // the person's left
        let up = Vector3::z();
        [
            centre - left * 0.032 + up * 0.03,
            centre + left * 0.032 + up * 0.03,
            centre,
            centre - left * 0.025 - up * 0.04,
            centre + left * 0.025 - up * 0.04,
        ]
    }

    fn detect(c: &Camera, slot: usize, f: &[Vector3<f64>; 5]) -> Detection {
        let lm = [0, 1, 2, 3, 4].map(|p| c.project(&f[p]).0);
        Detection {
            slot,
            landmarks: lm,
            size: 100.0,
        }
    }

    fn scene() -> (Vec<Camera>, Vec<[Vector3<f64>; 5]>) {
        let target = Vector3::new(0.0, 0.0, 1.6);
        let cams: Vec<Camera> = (0..4)
            .map(|i| {
                let a = 0.4 * i as f64 - 0.6;
                cam(Vector3::new(3.0 * a.cos(), 3.0 * a.sin(), 1.7), target, i)
            })
            .collect();
        let faces = vec![
            face(Vector3::new(0.0, 0.0, 1.6), Vector3::x()),
            face(Vector3::new(0.3, 0.9, 1.5), Vector3::x()),
            face(Vector3::new(-0.5, -0.8, 1.7), Vector3::x()),
        ];
        (cams, faces)
    }

    #[test]
    fn ransac_groups_faces_without_two_detections_of_one_camera() {
        let (cams, faces) = scene();
        let mut dets = Vec::new();
        let mut truth = Vec::new();
        for (s, c) in cams.iter().enumerate() {
            for (j, f) in faces.iter().enumerate() {
                dets.push(detect(c, s, f));
                truth.push(j);
            }
        }
        let a = associate(&cams, &dets, &[], &AssociationOptions::default()).unwrap();
        assert_eq!(a.anchor.len(), 3);
        for i in 0..dets.len() {
            for k in 0..dets.len() {
                let same = a.label[i] == a.label[k];
                assert_eq!(same, truth[i] == truth[k], "detections {i} and {k}");
            }
        }
        let n = a.anchor.len();
        let sig = vec![1.0; dets.len()];
        let tri = triangulate_faces(&cams, &dets, &sig, &a.label, n).unwrap();
        for (i, l) in a.label.iter().enumerate() {
            let f = tri[l.unwrap()].unwrap();
            for (x, t) in f.x.iter().zip(faces[truth[i]].iter()) {
                assert!((x - t).norm() < 1e-6);
            }
            let (o, v, s) = gaze_from_landmarks(&f.x, &f.std).unwrap();
            assert!((v - Vector3::x()).norm() < 1e-6, "{v}");
            assert!((o - (faces[truth[i]][0] + faces[truth[i]][1]) * 0.5).norm() < 1e-6);
            assert!(s > 0.0 && s < 0.5);
        }
    }

    #[test]
    fn anchors_claim_faces_and_single_views_stay_alone() {
        let (cams, faces) = scene();
        let mut dets = vec![
            detect(&cams[0], 0, &faces[0]),
            detect(&cams[1], 1, &faces[0]),
        ];
        dets.push(detect(&cams[2], 2, &faces[1])); // seen once only
        let anchor = Anchor {
            centre: faces[0][2] + Vector3::new(-0.05, 0.0, 0.08),
            slot: 3,
            gate: 0.25,
        };
        let a = associate(&cams, &dets, &[anchor], &AssociationOptions::default()).unwrap();
        assert_eq!(a.label[0], a.label[1]);
        assert_eq!(a.anchor[a.label[0].unwrap()], Some(0));
        assert_eq!(a.label[2], None);
        let bad = Anchor {
            centre: anchor.centre,
            slot: 9,
            gate: 0.25,
        };
        assert!(associate(&cams, &dets, &[bad], &AssociationOptions::default()).is_err());
    }

    #[test]
    fn head_cameras_claim_before_tracks() {
        // a track whose predicted eye midpoint sits right on a wearer's face must not take
        // it from the wearer's own camera, 6 cm away (rendered circle 136: a ghost track of
        // two people's faces took a wearer's detections for 30 instants)
        let (cams, faces) = scene();
        let dets = vec![
            detect(&cams[0], 0, &faces[0]),
            detect(&cams[1], 1, &faces[0]),
        ];
        let wearer = Anchor {
            centre: (faces[0][0] + faces[0][1]) * 0.5 + Vector3::new(0.0, 0.0, 0.06),
            slot: 3,
            gate: 0.25,
        };
        let track = Anchor {
            centre: (faces[0][0] + faces[0][1]) * 0.5,
            slot: usize::MAX,
            gate: 0.12,
        };
        for anchors in [[track, wearer], [wearer, track]] {
            let a = associate(&cams, &dets, &anchors, &AssociationOptions::default()).unwrap();
            let w = anchors.iter().position(|x| x.slot == 3).unwrap();
            assert_eq!(a.label[0], a.label[1]);
            assert_eq!(a.anchor[a.label[0].unwrap()], Some(w));
        }
    }

    #[test]
    fn tracks_do_not_keep_phantom_faces() {
        // what the detections of two people, each seen by one camera, triangulate to where
        // the lines of sight cross: a face squashed to eyes-to-mouth 0.45 × the eye distance
        // (measured on a rendered circle); a track anchored there must not claim it
        let (cams, faces) = scene();
        let mut ghost = faces[0];
        let mid = (ghost[0] + ghost[1]) * 0.5;
        for p in ghost.iter_mut().skip(2) {
            p.z = mid.z + (p.z - mid.z) * 0.45 / 1.1;
        }
        let dets = vec![detect(&cams[0], 0, &ghost), detect(&cams[2], 2, &ghost)];
        let track = Anchor {
            centre: mid,
            slot: usize::MAX,
            gate: 0.12,
        };
        let a = associate(&cams, &dets, &[track], &AssociationOptions::default()).unwrap();
        assert_eq!(
            a.label,
            vec![None, None],
            "neither claimed nor paired by RANSAC"
        );
        assert!(a.anchor.is_empty());
        let loose = AssociationOptions {
            shape: (0.3, 1.6),
            ..AssociationOptions::default()
        };
        let a = associate(&cams, &dets, &[track], &loose).unwrap();
        assert_eq!(a.label, vec![Some(0), Some(0)]);
        assert_eq!(a.anchor, vec![Some(0)]);
        // a real face the track claims stays claimed, and the next group keeps its index
        let real = vec![
            detect(&cams[0], 0, &faces[0]),
            detect(&cams[2], 2, &faces[0]),
            detect(&cams[1], 1, &faces[1]),
            detect(&cams[3], 3, &faces[1]),
        ];
        let a = associate(&cams, &real, &[track], &AssociationOptions::default()).unwrap();
        assert_eq!(a.label, vec![Some(0), Some(0), Some(1), Some(1)]);
        assert_eq!(a.anchor, vec![Some(0), None]);
        // a track that also claimed another person's face, 9 cm beside its own, keeps the
        // two views that agree; the other sits the instant out
        // (boxes of 48 px, a face's at 3 m)
        let beside = face(faces[0][2] + Vector3::new(0.0, 0.09, 0.0), Vector3::x());
        let mixed: Vec<Detection> = [(0, &faces[0]), (2, &faces[0]), (1, &beside)]
            .into_iter()
            .map(|(s, f)| Detection {
                size: 48.0,
                ..detect(&cams[s], s, f)
            })
            .collect();
        let a = associate(&cams, &mixed, &[track], &AssociationOptions::default()).unwrap();
        assert_eq!(a.label, vec![Some(0), Some(0), None]);
        assert_eq!(a.anchor, vec![Some(0)]);
    }

    #[test]
    fn temporal_refinement_smooths_noise() {
        let (cams, _) = scene();
        let t_len = 30;
        let truth: Vec<[Vector3<f64>; 5]> = (0..t_len)
            .map(|t| face(Vector3::new(0.01 * t as f64, 0.0, 1.6), Vector3::x()))
            .collect();
        let mut obs = Vec::new();
        let mut x0 = Vec::new();
        let mut seed = 1u64;
        let mut noise = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 3.0
        };
        for (t, f) in truth.iter().enumerate() {
            let mut views = Vec::new();
            for (s, c) in cams.iter().enumerate().take(2) {
                let mut d = detect(c, s, f);
                for l in d.landmarks.iter_mut() {
                    *l += Vector2::new(noise(), noise());
                }
                obs.push((t, s, d.landmarks, 1.0));
                views.push(d);
            }
            let refs: Vec<&Detection> = views.iter().collect();
            x0.push(triangulate_face(&cams, &refs, &[1.0, 1.0]).unwrap().x);
        }
        let err = |x: &[[Vector3<f64>; 5]]| -> f64 {
            x.iter()
                .zip(&truth)
                .map(|(a, b)| (a[2] - b[2]).norm())
                .sum::<f64>()
                / t_len as f64
        };
        let (xr, std) = refine_track(&cams, &obs, &x0, 1e4, 1e4, 5).unwrap();
        assert!(err(&xr) < 0.7 * err(&x0), "{} vs {}", err(&xr), err(&x0));
        assert!(std
            .iter()
            .all(|s| s.iter().all(|v| v.is_finite() && *v > 0.0)));
        let (x_same, _) = refine_track(&cams, &obs, &x0, 0.0, 0.0, 5).unwrap();
        assert!((err(&x_same) - err(&x0)).abs() < 1e-6);
    }
}
