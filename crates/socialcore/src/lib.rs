//! # socialcore
//!
//! The numeric core of [socialcam](https://github.com/socialcam/socialcam): geometry of
//! social cameras and the solvers of H. S. Park's thesis *Social Scene Understanding from
//! Social Cameras* (equation numbers in the docs refer to it). Pure Rust on nalgebra, faer
//! and rayon; the Python binding lives in a separate crate.
//!
//! ```
//! use nalgebra::{Matrix3, Vector3};
//! use socialcore::geometry::{Camera, triangulate_point, LmOptions};
//!
//! let k = Matrix3::new(500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0);
//! let a = Camera::new(k, Matrix3::identity(), Vector3::new(-1.0, 0.0, -5.0), 0)?;
//! let b = Camera::new(k, Matrix3::identity(), Vector3::new(1.0, 0.0, -5.0), 1)?;
//! let x = Vector3::new(0.1, 0.2, 0.3);
//! let pixels = [Some(a.project(&x).0), Some(b.project(&x).0)];
//! let t = triangulate_point(&[a, b], &pixels, true, &LmOptions::default())?;
//! assert!((t.x - x).norm() < 1e-9);
//! # Ok::<(), socialcore::Error>(())
//! ```

pub mod articulated;
pub mod basis;
pub mod bqp;
pub mod error;
pub mod geometry;
pub mod interrupt;
pub mod trajectory;
// issue 6: gaze field (thesis Chapter 7)
pub mod gazefield;
// issue 10: ego-motion gaze calibration (thesis Sec 3.2.1)
pub mod gaze;

pub use error::{Error, Result};
pub mod saliency;
// issue 11: 3D faces and their gaze (thesis Sec 3.2.2)
pub mod faces;
