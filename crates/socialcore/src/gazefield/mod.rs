//! The gaze field (thesis Chapter 7): social charges pull the primary gaze of the members
//! of a scene like an electric field, selectively (the strongest charge wins, Eq 7.6), and
//! the gaze direction at any place and time follows a von Mises–Fisher mixture (Eq 7.7).
//! The charges are estimated from observed gaze by EM, per frame (Eq 7.10–7.13) or over a
//! time window with a temporal filter (Eq 7.14).
//!
//! ```
//! use nalgebra::Vector3;
//! use socialcore::gazefield::{em_frame, EmOptions, GazeField, GazeRay, SocialCharge};
//!
//! // Four people look at a charge at the origin.
//! let target = Vector3::new(0.0, 0.0, 1.0);
//! let rays: Vec<GazeRay> = [(2.0, 0.0), (-2.0, 0.0), (0.0, 2.0), (0.0, -2.0)]
//!     .iter()
//!     .map(|&(x, y)| {
//!         let p = Vector3::new(x, y, 1.6);
//!         GazeRay::new(p, (target - p).normalize())
//!     })
//!     .collect();
//! let fit = em_frame(&rays, &[Vector3::new(0.3, -0.2, 1.2)], &EmOptions::default())?;
//! assert!((fit.charges[0].position - target).norm() < 1e-6);
//! let field = GazeField::new(fit.charges, 20.0)?;
//! let v = field.most_likely_direction(&Vector3::new(1.0, 1.0, 1.0))?.unwrap();
//! assert!((v - Vector3::new(-1.0, -1.0, 0.0).normalize()).norm() < 1e-6);
//! # Ok::<(), socialcore::Error>(())
//! ```

pub mod banded;
pub mod batch;
pub mod em;
pub mod field;
pub mod init;
pub mod vmf;

pub use em::{
    em_frame, em_frames, em_window, em_windows, split_windows, validate_rays, EmOptions, FrameFit,
    GazeRay, Kappa, Membership, TemporalFilter, Window, WindowFit, WindowFrame, WindowJob,
};
pub use field::{
    charge_field, validate_charges, validate_kappa, Component, GazeField, SocialCharge,
};
pub use init::{associate, init_charges, init_window, init_window_from_candidates};
