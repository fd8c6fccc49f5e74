//! `gnomon._kernel`: thin PyO3 bindings of `gnomon-core`, one module per area.
//!
//! Arrays are borrowed (copied only when not C-contiguous) and the GIL is
//! released around every kernel call (`arrays`). Errors are the exception classes of
//! `gnomon.errors`, one per `KernelError` variant (all `GnomonError`s and
//! `ValueError`s), each message naming what was expected and what was given:
//! bad arrays raise `KernelArrayError` (`errors`). The tracker's results are typed
//! classes of arrays (`results`). No numerics here: see `gnomon-core`.

use pyo3::prelude::*;

mod arrays;
mod camera;
mod deblock;
mod errors;
mod lines;
mod live;
mod lut;
mod mesh;
mod noise;
mod results;
mod retime;
mod surface;
mod tracker;
mod triangulate;

/// Add each `module::function` (a `#[pyfunction]`) to `m`, in order.
macro_rules! add_functions {
    ($m:ident: $($module:ident::$function:ident),+ $(,)?) => {
        $($m.add_function(wrap_pyfunction!($module::$function, $m)?)?;)+
    };
}

#[pymodule]
fn _kernel(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<tracker::TemporalTracker>()?;
    m.add_class::<results::PyShadowTimes>()?;
    m.add_class::<results::PySecondDips>()?;
    m.add_class::<live::PyFinishedPixels>()?;
    // in the order of the module's `__all__`
    add_functions! { m:
        triangulate::triangulate, triangulate::ray_plane_angles, triangulate::depth_sigma,
        triangulate::completion_sigma, lines::frame_lines, lines::isochrone_crossings,
        mesh::grid_faces, mesh::clean_faces, mesh::obj_text, surface::grid_normals,
        surface::stl_records, retime::retime_rows, retime::retime_rows_sigma,
        retime::average_across, triangulate::triangulate_depth, surface::world_points,
        camera::ray_map, surface::lit_median, surface::lit_median_between, noise::clipped_fit_step, noise::noise_samples,
        surface::fuse_supported, tracker::simd_path, tracker::simd_paths, lines::line_times,
        deblock::deblock_interpolate, lut::lut_lookup,
    }
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
