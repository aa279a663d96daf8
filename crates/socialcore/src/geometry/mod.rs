//! Multi-view geometry: cameras, triangulation, rays, similarity alignment.

pub mod camera;
pub mod rays;
pub mod similarity;
pub mod triangulate;

pub use camera::Camera;
pub use rays::{line_point_distance, perspective_distance, perspective_distance_norm, ray_sphere};
pub use similarity::{align_similarity, Similarity};
pub use triangulate::{
    refine_point, triangulate_batch, triangulate_dlt, triangulate_point, LmOptions, Triangulated,
};
