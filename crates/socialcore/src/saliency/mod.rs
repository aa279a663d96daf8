//! Social saliency and social charges: 3D joint attention (thesis Chapter 6, gaze model of
//! Sec 3.1).
//!
//! A frame's gaze rays ([`GazeRays`]: eye centres `p`, unit directions `v`, bandwidths `h`)
//! induce the social saliency field of Eq 6.1–6.4 ([`saliency_at`], [`saliency_grid`]).
//! Its modes, found by the ray mean-shift of Eq 6.5–6.7 ([`find_charges`],
//! [`find_charges_sequence`]), are the social charges; their membership vectors (Eq 6.8)
//! are clustered over time with classic mean-shift to give tracks ([`track_charges`],
//! Sec 6.1.3).
//!
//! ```
//! use nalgebra::Vector3;
//! use socialcore::saliency::{find_charges, GazeRays, ModeOptions};
//!
//! // Three people look at the origin from a circle of radius 3 m.
//! let target = Vector3::zeros();
//! let p: Vec<Vector3<f64>> = (0..3)
//!     .map(|i| {
//!         let a = i as f64 * 2.1;
//!         Vector3::new(3.0 * a.cos(), 3.0 * a.sin(), 0.5)
//!     })
//!     .collect();
//! let v: Vec<Vector3<f64>> = p.iter().map(|p| (target - p).normalize()).collect();
//! let rays = GazeRays::new(p, v, vec![0.1; 3], None)?;
//! let charges = find_charges(&rays, &ModeOptions::default(), 7)?;
//! assert_eq!(charges.len(), 1);
//! assert!((charges[0].position - target).norm() < 1e-3);
//! assert_eq!(charges[0].members, vec![0, 1, 2]);
//! # Ok::<(), socialcore::Error>(())
//! ```

pub mod field;
pub mod modes;
mod partition;
pub mod tracking;
mod window;

pub use field::{ray_density, ray_hessian, saliency, saliency_at, saliency_grid, Grid};
pub use modes::{
    diagnose_window, find_charges, find_charges_sequence, Charge, Ellipsoid, Membership,
    ModeOptions,
};
pub use tracking::{track_charges, TrackOptions, Tracking};

use crate::error::{ensure_finite, Error, Result};
use nalgebra::Vector3;

/// How far `‖v‖` may be from 1 before a direction counts as not unit length.
pub const UNIT_TOLERANCE: f64 = 1e-6;

/// The primary gaze rays of one frame (Sec 3.1): ray `i` starts at the eye centre `p[i]`,
/// points along the unit vector `v[i]`, and has bandwidth `h[i] > 0`, the standard
/// deviation of eye-in-head deviation on the plane at unit distance from the eye.
#[derive(Debug, Clone, PartialEq)]
pub struct GazeRays {
    p: Vec<Vector3<f64>>,
    v: Vec<Vector3<f64>>,
    h: Vec<f64>,
    ids: Vec<i64>,
    /// Per-ray constants of the hot loops: `1/h²`, `1/h³` and `1/(h√2π)`.
    inv_h2: Vec<f64>,
    inv_h3: Vec<f64>,
    peak: Vec<f64>,
}

impl GazeRays {
    /// Validates and stores a frame's rays. `ids` default to `0..N`.
    ///
    /// Errors (`InvalidInput`): no rays; lengths that differ; a non-finite value; a
    /// direction whose norm differs from 1 by more than [`UNIT_TOLERANCE`]; `h ≤ 0`.
    pub fn new(
        p: Vec<Vector3<f64>>,
        v: Vec<Vector3<f64>>,
        h: Vec<f64>,
        ids: Option<Vec<i64>>,
    ) -> Result<Self> {
        let n = p.len();
        if n == 0 {
            return Err(Error::invalid("p", "needs at least one gaze ray, got 0"));
        }
        if v.len() != n {
            return Err(Error::invalid(
                "v",
                format!("has {} directions for {n} ray origins", v.len()),
            ));
        }
        if h.len() != n {
            return Err(Error::invalid(
                "h",
                format!("has {} bandwidths for {n} rays", h.len()),
            ));
        }
        for (name, pts) in [("p", &p), ("v", &v)] {
            for x in pts.iter() {
                ensure_finite(name, x.as_slice())?;
            }
        }
        ensure_finite("h", &h)?;
        if let Some(i) = v
            .iter()
            .position(|d| (d.norm() - 1.0).abs() > UNIT_TOLERANCE)
        {
            return Err(Error::invalid(
                "v",
                format!(
                    "direction {i} has norm {} (must be unit; normalise it first)",
                    v[i].norm()
                ),
            ));
        }
        if let Some(i) = h.iter().position(|&x| x <= 0.0) {
            return Err(Error::invalid(
                "h",
                format!("bandwidth {i} is {} (must be > 0)", h[i]),
            ));
        }
        let ids = match ids {
            Some(ids) => {
                if ids.len() != n {
                    return Err(Error::invalid(
                        "ids",
                        format!("has {} ids for {n} rays", ids.len()),
                    ));
                }
                ids
            }
            None => (0..n as i64).collect(),
        };
        let inv_h2 = h.iter().map(|h| 1.0 / (h * h)).collect();
        let inv_h3 = h.iter().map(|h| 1.0 / (h * h * h)).collect();
        let peak = h.iter().map(|h| field::INV_SQRT_2PI / h).collect();
        Ok(GazeRays {
            p,
            v,
            h,
            ids,
            inv_h2,
            inv_h3,
            peak,
        })
    }

    /// Builds rays from flat row-major `(N, 3)` buffers, as they come from NumPy.
    pub fn from_flat(p: &[f64], v: &[f64], h: &[f64], ids: Option<Vec<i64>>) -> Result<Self> {
        if p.len() % 3 != 0 || v.len() % 3 != 0 {
            return Err(Error::invalid(
                "p",
                "expected (N, 3) arrays of origins and directions",
            ));
        }
        let to_vecs = |a: &[f64]| {
            a.chunks_exact(3)
                .map(|c| Vector3::new(c[0], c[1], c[2]))
                .collect::<Vec<_>>()
        };
        Self::new(to_vecs(p), to_vecs(v), h.to_vec(), ids)
    }

    /// Number of rays `N`.
    pub fn len(&self) -> usize {
        self.p.len()
    }
    /// Always false: a `GazeRays` holds at least one ray.
    pub fn is_empty(&self) -> bool {
        self.p.is_empty()
    }
    /// Eye centres, metres.
    pub fn origins(&self) -> &[Vector3<f64>] {
        &self.p
    }
    /// Unit directions.
    pub fn directions(&self) -> &[Vector3<f64>] {
        &self.v
    }
    /// Bandwidths (standard deviation on the unit plane, Sec 3.1).
    pub fn bandwidths(&self) -> &[f64] {
        &self.h
    }
    /// Person ids.
    pub fn ids(&self) -> &[i64] {
        &self.ids
    }
}
