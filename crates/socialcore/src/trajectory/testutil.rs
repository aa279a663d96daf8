//! Synthetic scenes with known ground truth for the trajectory tests and benches.

use crate::geometry::Camera;
use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub(crate) fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// A standard normal draw (Box–Muller).
pub(crate) fn gauss(r: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = r.random::<f64>().max(1e-300);
    let u2: f64 = r.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A 1280×720 camera with focal length 1000 px at `c` looking at `target` (world y up).
pub(crate) fn look_at(c: Vector3<f64>, target: Vector3<f64>, index: usize) -> Camera {
    let k = Matrix3::new(1000.0, 0.0, 640.0, 0.0, 1000.0, 360.0, 0.0, 0.0, 1.0);
    let z = (target - c).normalize();
    let x = z.cross(&Vector3::y()).normalize();
    let y = z.cross(&x);
    let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
    Camera::new(k, r, c, index).expect("valid synthetic camera")
}

/// "Many photographers": each frame is taken from a random place on a ring of radius
/// 4–6 m around the scene, 1.2–1.8 m high, looking at the scene centre.
pub(crate) fn random_cameras(r: &mut ChaCha8Rng, f: usize) -> Vec<Camera> {
    (0..f)
        .map(|i| {
            let a: f64 = r.random::<f64>() * std::f64::consts::TAU;
            let rad = 4.0 + 2.0 * r.random::<f64>();
            let h = 1.2 + 0.6 * r.random::<f64>();
            look_at(
                Vector3::new(rad * a.cos(), h, rad * a.sin()),
                Vector3::new(0.0, 1.0, 0.0),
                i,
            )
        })
        .collect()
}

/// A slow, smooth camera: an arc of `sweep` radians at 5 m.
pub(crate) fn arc_cameras(f: usize, sweep: f64) -> Vec<Camera> {
    (0..f)
        .map(|i| {
            let a = sweep * i as f64 / f as f64;
            look_at(
                Vector3::new(5.0 * a.cos(), 1.5, 5.0 * a.sin()),
                Vector3::new(0.0, 1.0, 0.0),
                i,
            )
        })
        .collect()
}

/// Uniform capture times at `fps`.
pub(crate) fn times(f: usize, fps: f64) -> Vec<f64> {
    (0..f).map(|i| i as f64 / fps).collect()
}

/// A smooth random trajectory near the scene centre: a few sinusoids per coordinate,
/// 0.1–0.5 m amplitude, 0.1–`max_hz` Hz.
pub(crate) fn smooth_trajectory(r: &mut ChaCha8Rng, t: &[f64], max_hz: f64) -> Vec<Vector3<f64>> {
    let mut comps = Vec::new();
    for _ in 0..3 {
        let mut c = Vec::new();
        for _ in 0..3 {
            let amp = 0.1 + 0.4 * r.random::<f64>();
            let hz = 0.1 + (max_hz - 0.1) * r.random::<f64>();
            let ph = r.random::<f64>() * std::f64::consts::TAU;
            c.push((amp, hz, ph));
        }
        comps.push(c);
    }
    t.iter()
        .map(|&tt| {
            let mut x = Vector3::new(0.0, 1.0, 0.0);
            for (axis, c) in comps.iter().enumerate() {
                for &(amp, hz, ph) in c {
                    x[axis] += amp * (std::f64::consts::TAU * hz * tt + ph).sin();
                }
            }
            x
        })
        .collect()
}

/// A walking-like trajectory (a foot marker): forward progress at 0.5 m/s with a 1 Hz
/// stride, lifting 0.15 m and swaying 0.05 m, centred on the scene.
pub(crate) fn walking_trajectory(t: &[f64]) -> Vec<Vector3<f64>> {
    let dur = t.iter().copied().fold(0.0, f64::max);
    t.iter()
        .map(|&tt| {
            let ph = std::f64::consts::TAU * tt;
            Vector3::new(
                0.5 * (tt - 0.5 * dur) + 0.25 * ph.sin(),
                0.1 + 0.075 * (1.0 - ph.cos()),
                0.05 * (0.5 * ph).sin(),
            )
        })
        .collect()
}

/// Pixels `(F, 2)` row-major of a trajectory with Gaussian noise of `sigma` px.
pub(crate) fn project(
    cams: &[Camera],
    pts: &[Vector3<f64>],
    sigma: f64,
    r: &mut ChaCha8Rng,
) -> Vec<f64> {
    let mut out = Vec::with_capacity(2 * pts.len());
    for (c, p) in cams.iter().zip(pts) {
        let (u, depth) = c.project(p);
        assert!(depth > 0.0, "synthetic point behind a camera");
        out.push(u.x + sigma * gauss(r));
        out.push(u.y + sigma * gauss(r));
    }
    out
}

/// Marks a random `fraction` of the frames missing (NaN rows).
pub(crate) fn drop_random(px: &mut [f64], fraction: f64, r: &mut ChaCha8Rng) {
    for row in px.chunks_mut(2) {
        if r.random::<f64>() < fraction {
            row[0] = f64::NAN;
            row[1] = f64::NAN;
        }
    }
}

/// RMS 3D error between two trajectories.
pub(crate) fn rms_error(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    (a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).norm_squared())
        .sum::<f64>()
        / a.len() as f64)
        .sqrt()
}
