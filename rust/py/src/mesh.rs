//! The mesh on the pixel grid, its clean-up and its OBJ text (see `gnomon-core`'s `mesh`).

use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyList};

use crate::arrays::Extent::{Any, Exactly};
use crate::arrays::{borrow, grid, on_slices, rows};
use crate::errors::kernel_error;

/// `(faces (F', 3) int32, source (V',) int64)`.
type FacesAndSources<'py> = (Bound<'py, PyArray2<i32>>, Bound<'py, PyArray1<i64>>);

/// Faces (F, 3) int32 of the grid mesh of the valid pixels (see `gnomon_core::grid_faces`).
#[pyfunction]
#[pyo3(signature = (valid, depth, sigma, max_relative_jump, sigma_factor = 5.0))]
pub(crate) fn grid_faces<'py>(
    py: Python<'py>, valid: &Bound<'py, PyAny>, depth: &Bound<'py, PyAny>,
    sigma: &Bound<'py, PyAny>, max_relative_jump: f32, sigma_factor: f32,
) -> PyResult<Bound<'py, PyArray2<i32>>> {
    let (valid, h, w) = grid::<u8>(valid, "valid")?;
    let depth = borrow::<f32, 2>(depth, "depth", [Exactly(h), Exactly(w)])?;
    let sigma = borrow::<f32, 2>(sigma, "sigma", [Exactly(h), Exactly(w)])?;
    let faces = on_slices!(py, [valid, depth, sigma] => {
        gnomon_core::grid_faces(valid, depth, sigma, w.max(1), max_relative_jump, sigma_factor)
    })?;
    rows(py, faces)
}

/// Drop small pieces and split non-manifold vertices (see `gnomon_core::clean_faces`):
/// the new faces (F', 3) int32 and the source vertex of each new vertex (V',) int64. With
/// `pixels` (V,) int64, each vertex's row-major pixel in a grid `width` wide, the same result
/// through the grid's edge slots when the mesh is on the grid (`gnomon_core::clean_grid_faces`).
#[pyfunction]
#[pyo3(signature = (n_vertices, faces, min_vertices, pixels = None, width = 0))]
pub(crate) fn clean_faces<'py>(
    py: Python<'py>, n_vertices: usize, faces: &Bound<'py, PyAny>, min_vertices: usize,
    pixels: Option<&Bound<'py, PyAny>>, width: usize,
) -> PyResult<FacesAndSources<'py>> {
    let faces = borrow::<i32, 2>(faces, "faces", [Any("F"), Exactly(3)])?;
    let clean = match pixels {
        None => on_slices!(py, [faces] => {
            gnomon_core::clean_faces(n_vertices, gnomon_core::triangles(faces)?, min_vertices)
        })?,
        Some(p) => {
            let pixels = borrow::<i64, 1>(p, "pixels", [Exactly(n_vertices)])?;
            on_slices!(py, [faces, pixels] => {
                let grid = gnomon_core::VertexPixels { pixel: pixels, width };
                gnomon_core::clean_grid_faces(n_vertices, gnomon_core::triangles(faces)?, min_vertices, Some(grid))
            })?
        }
    };
    Ok((rows(py, clean.faces)?, clean.source.into_pyarray(py)))
}

/// The body of a Wavefront OBJ file (see `gnomon_core::obj_text`): bytes, or with `as_parts` a
/// list of uint8 arrays (its blocks of lines, in order, not copied).
#[pyfunction]
#[pyo3(signature = (vertices, vertex_decimals, uv, normals, faces, as_parts = false))]
pub(crate) fn obj_text<'py>(
    py: Python<'py>, vertices: &Bound<'py, PyAny>, vertex_decimals: usize,
    uv: Option<&Bound<'py, PyAny>>, normals: Option<&Bound<'py, PyAny>>, faces: &Bound<'py, PyAny>,
    as_parts: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let vertices = borrow::<f64, 2>(vertices, "vertices", [Any("V"), Exactly(3)])?;
    let nv = vertices.shape()[0];
    let uv = uv.map(|a| borrow::<f64, 2>(a, "uv", [Exactly(nv), Exactly(2)])).transpose()?;
    let normals =
        normals.map(|a| borrow::<f64, 2>(a, "normals", [Exactly(nv), Exactly(3)])).transpose()?;
    let faces = borrow::<i64, 2>(faces, "faces", [Any("F"), Exactly(3)])?;
    let owned = |a: &PyReadonlyArray2<'py, f64>| a.as_array().iter().copied().collect::<Vec<f64>>();
    let (v, t, n, f) = (
        owned(&vertices),
        uv.as_ref().map(owned),
        normals.as_ref().map(owned),
        faces.as_array().iter().copied().collect::<Vec<i64>>(),
    );
    let parts = py
        .detach(|| gnomon_core::obj_text_parts(&v, vertex_decimals, t.as_deref(), n.as_deref(), &f))
        .map_err(kernel_error)?;
    if as_parts {
        // no copy: each block of lines becomes a uint8 array that owns it
        return Ok(PyList::new(py, parts.into_iter().map(|p| p.into_pyarray(py)))?.into_any());
    }
    // one copy, straight into the bytes object
    let len = parts.iter().map(Vec::len).sum();
    PyBytes::new_with(py, len, |buf| {
        let mut at = 0;
        for p in &parts {
            buf[at..at + p.len()].copy_from_slice(p);
            at += p.len();
        }
        Ok(())
    })
    .map(Bound::into_any)
}
