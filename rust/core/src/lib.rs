//! gnomon-core: the per-pixel numerics of the Gnomon shadow scanner
//! (Bouguet & Perona, "3D photography on your desk", 1998).
//!
//! * [`TemporalTracker`]: streaming per-pixel shadow times from a sequence of
//!   grey frames, `O(pixels)` memory whatever the number of frames;
//! * the live watch ([`TemporalTracker::watch`], [`live`]): pixels whose
//!   shadow has passed, with provisional times, as soon as it has passed;
//! * [`triangulate`]: camera rays ∩ interpolated shadow planes ([`triangulate_depth`]: their Z only);
//!   [`depth_sigma`]: their σZ;
//! * [`grid_faces`], [`clean_faces`], [`obj_text`]: the mesh on the pixel grid, its clean-up, its OBJ text;
//! * [`isochrone_crossings`], [`frame_lines`], [`line_times`]: where the shadow-time map crosses each frame, each
//!   frame's robust shadow line on a reference plane;
//! * [`retime_rows`], [`retime_rows_sigma`]: a fast sweep's shadow times between the isochrones (and their σ);
//!   [`average_across`]: the re-timed times averaged across the sweep;
//! * [`world_points`], [`grid_normals`], [`stl_records`]: the surface's world points and normals on the
//!   pixel grid, a mesh's binary STL records;
//! * [`noise_samples`], [`clipped_fit_step`]: the image-noise estimate's samples and the steps of its
//!   clipped fit, in numpy's float32 order;
//! * [`ray_map`]: the unit ray of every pixel of OpenCV's 5-coefficient camera (Newton);
//! * [`deblock_interpolate`]: a compressed video's shadow times between its codec blocks' centres;
//! * [`lut_lookup`]: a per-code table at each level's code in a sorted decoding table;
//! * [`Plane`], [`Ray`]: the geometry, in the camera frame.
//!
//! Pure Rust, no Python types; every function on user data returns
//! `Result<_, KernelError>`.

pub mod camera;
pub mod crossing;
pub mod deblock;
pub mod error;
pub mod geometry;
pub mod intensity;
pub mod lines;
pub mod live;
pub mod lut;
pub mod mesh;
pub mod noise;
pub mod retime;
mod ring;
pub mod sample;
pub mod simd;
pub mod surface;
pub mod tracker;
pub mod triangulate;

pub use camera::ray_map;
pub use deblock::{deblock_interpolate, BlockLayout};
pub use error::KernelError;
pub use geometry::{Plane, Ray};
pub use intensity::NORMALISED_SCALE;
pub use lines::{frame_lines, isochrone_crossings, line_times, Crossings, FrameLines, LineParams};
pub use live::{FinishedPixel, WatchParams};
pub use lut::lut_lookup;
pub use mesh::{
    clean_faces, clean_grid_faces, grid_faces, obj_text, obj_text_parts, triangles, CleanMesh,
    VertexPixels,
};
pub use noise::{clipped_fit_step, noise_samples, pairwise_sum, ClipFit, NoiseSamples};
pub use retime::{
    average_across, retime_rows, retime_rows_sigma, RetimeParams, Retimed, RetimedSigma,
};
pub use sample::Sample;
pub use simd::SimdPath;
pub use surface::{
    fuse_supported, grid_normals, lit_median, lit_median_between, lit_median_channels, stl_records,
    world_points, STL_RECORD_BYTES,
};
pub use tracker::{
    find_crossing, Crossing, Edge, SecondDips, ShadowTimes, TemporalTracker, TrackerParams,
};
pub use triangulate::{
    completion_sigma, depth_sigma, plane_at, ray_plane_angles, triangulate, triangulate_depth,
    Completion, DepthSigma,
};
