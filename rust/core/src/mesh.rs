//! The triangle mesh on the pixel grid (docs/method.md, "Mesh") and its
//! connectivity clean-up, as the numpy definitions in `gnomon.geometry.meshing` state
//! them, with the same results element for element (faces, vertex order and
//! vertex copies): [`grid_faces`] cuts the grid at depth jumps,
//! [`clean_faces`] drops small edge-connected pieces and splits non-manifold
//! vertices, [`obj_text`] formats a mesh as Wavefront OBJ text.
//!
//! Invariants: vertices are numbered by their pixel's rank among the valid
//! pixels (row-major); faces are `[i32; 3]`, counter-clockwise seen from the
//! camera; connectivity is "shares an edge" (two vertex indices).

use rayon::prelude::*;

use crate::error::KernelError;

/// Rows of quads (or faces, corners, text lines) per parallel work item.
const ROWS_PER_TASK: usize = 8;
const ITEMS_PER_TASK: usize = 16384;

/// Disjoint sets over `0..n` (path halving, union by index: the smaller root wins).
struct UnionFind {
    parent: Vec<u32>,
}

impl UnionFind {
    fn new(n: usize) -> Self {
        UnionFind {
            parent: (0..n as u32).collect(),
        }
    }

    fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let up = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = up;
            x = up;
        }
        x
    }

    /// Every element's root, in its own slot: the parent table, each entry set to its root
    /// (a full path compression, which leaves every set as it was).
    fn into_roots(mut self) -> Vec<u32> {
        for i in 0..self.parent.len() as u32 {
            let root = self.find(i);
            self.parent[i as usize] = root;
        }
        self.parent
    }

    fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
            self.parent[hi as usize] = lo;
        }
    }
}

/// The faces' undirected edges bucketed by their smaller vertex (a counting sort, linear
/// time): bucket `lo` holds `(larger vertex, face)` of every edge at `lo`, in face order (each
/// face's edges `(f0, f1)`, `(f1, f2)`, `(f2, f0)`). A bucket holds a handful on a mesh.
struct EdgeBuckets {
    start: Vec<u32>,
    slot: Vec<(u32, u32)>,
}

impl EdgeBuckets {
    /// Invariant: every vertex index is in `0..n` (checked by the caller) and `3·faces` fits a u32.
    fn new(n: usize, faces: &[[i32; 3]]) -> Self {
        let edges = |f: &[i32; 3]| [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])];
        let mut start = vec![0u32; n + 1];
        for f in faces {
            for (a, b) in edges(f) {
                start[a.min(b) as usize + 1] += 1;
            }
        }
        for i in 0..n {
            start[i + 1] += start[i];
        }
        // Filled through `start[lo]` as the next free place of bucket `lo` (faces in order), which
        // moves each one to where bucket `lo + 1` starts; shifted back one place after.
        let mut slot = vec![(0u32, 0u32); 3 * faces.len()];
        for (i, f) in faces.iter().enumerate() {
            for (a, b) in edges(f) {
                let lo = a.min(b) as usize;
                slot[start[lo] as usize] = (a.max(b) as u32, i as u32);
                start[lo] += 1;
            }
        }
        start.copy_within(0..n, 1);
        start[0] = 0;
        EdgeBuckets { start, slot }
    }

    fn bucket(&self, lo: usize) -> &[(u32, u32)] {
        &self.slot[self.start[lo] as usize..self.start[lo + 1] as usize]
    }

    /// Link the faces that share an edge (each to the first earlier face in its bucket with it).
    fn link(&self, sets: &mut UnionFind) {
        for lo in 0..self.start.len() - 1 {
            let bucket = self.bucket(lo);
            for (i, &(hi, face)) in bucket.iter().enumerate() {
                if let Some(&(_, other)) = bucket[..i].iter().find(|e| e.0 == hi) {
                    sets.union(other, face);
                }
            }
        }
    }

    /// Interior edges (in two or more of the faces `keep` marks) at each vertex, `n` vertices.
    fn interior(&self, keep: &[bool]) -> Vec<u32> {
        let n = self.start.len() - 1;
        let mut interior = vec![0u32; n];
        for lo in 0..n {
            let bucket = self.bucket(lo);
            for (i, &(hi, face)) in bucket.iter().enumerate() {
                if !keep[face as usize] {
                    continue;
                }
                let kept_hi = |e: &&(u32, u32)| e.0 == hi && keep[e.1 as usize];
                let seen_before = bucket[..i].iter().any(|e| kept_hi(&e));
                if !seen_before && bucket[i + 1..].iter().any(|e| kept_hi(&e)) {
                    interior[lo] += 1;
                    interior[hi as usize] += 1;
                }
            }
        }
        interior
    }
}

/// The pixel grid a mesh's vertices lie on: `pixel[v]`, the row-major pixel of vertex `v`
/// (strictly increasing: vertices numbered by their pixel's rank), in rows `width` wide.
#[derive(Debug, Clone, Copy)]
pub struct VertexPixels<'a> {
    pub pixel: &'a [i64],
    pub width: usize,
}

/// A grid mesh's edges by their slot: `4·lo + step`, `lo` the edge's smaller vertex and
/// `step` which of the grid's four steps (`1`, `W − 1`, `W`, `W + 1` pixels) leads from its
/// pixel to the other end's. Two faces share an edge exactly when they share its slot (the
/// pixels strictly increase, so `lo` and the step name the other end), so this finds what
/// [`EdgeBuckets`] does with one table lookup per edge and no sort.
struct GridEdges<'a> {
    pixel: &'a [i64],
    width: i64,
    /// Each slot's faces (saturating at 255) and each vertex's interior edges, over all the
    /// faces: [`GridEdges::link`]'s, taken by [`GridEdges::interior`].
    counted: Option<(Vec<u8>, Vec<u32>)>,
}

impl<'a> GridEdges<'a> {
    /// The table when every edge of `faces` is one grid step between its ends' pixels, the
    /// pixels strictly increase and the grid is at least 3 wide (so the four steps differ);
    /// None otherwise (the caller buckets the edges instead). Invariant: vertex indices of
    /// `faces` are in `0..pixel.len()`.
    fn new(grid: VertexPixels<'a>, faces: &[[i32; 3]]) -> Option<Self> {
        let width = i64::try_from(grid.width).ok()?;
        if width < 3 || grid.pixel.windows(2).any(|p| p[0] >= p[1]) {
            return None;
        }
        let table = GridEdges {
            pixel: grid.pixel,
            width,
            counted: None,
        };
        let steps_ok = faces
            .par_iter()
            .all(|f| edges(f).iter().all(|&(a, b)| table.step(a, b).is_some()));
        steps_ok.then_some(table)
    }

    /// Which grid step leads from the pixel of `a`'s and `b`'s smaller vertex to the other's.
    fn step(&self, a: i32, b: i32) -> Option<usize> {
        let (lo, hi) = (a.min(b) as usize, a.max(b) as usize);
        match self.pixel[hi] - self.pixel[lo] {
            1 => Some(0),
            d if d == self.width - 1 => Some(1),
            d if d == self.width => Some(2),
            d if d == self.width + 1 => Some(3),
            _ => None,
        }
    }

    /// The edge's slot (invariant: [`GridEdges::new`] accepted its faces).
    fn slot(&self, a: i32, b: i32) -> usize {
        4 * a.min(b) as usize + self.step(a, b).unwrap_or(0)
    }

    /// Link the faces that share an edge (each to the first earlier face with it), and count
    /// every edge's faces and the interior edges (in two or more faces) at each vertex, kept in
    /// the table for [`GridEdges::interior`].
    fn link(&mut self, faces: &[[i32; 3]], sets: &mut UnionFind) {
        let n = self.pixel.len();
        let mut first = vec![u32::MAX; 4 * n];
        let mut count = vec![0u8; 4 * n];
        let mut interior = vec![0u32; n];
        for (i, f) in faces.iter().enumerate() {
            for (a, b) in edges(f) {
                let s = self.slot(a, b);
                if first[s] == u32::MAX {
                    first[s] = i as u32;
                } else {
                    sets.union(first[s], i as u32);
                }
                count[s] = count[s].saturating_add(1);
                if count[s] == 2 {
                    interior[a as usize] += 1;
                    interior[b as usize] += 1;
                }
            }
        }
        self.counted = Some((count, interior));
    }

    /// Interior edges (in two or more of the faces `keep` marks) at each vertex: those of all
    /// the faces ([`GridEdges::link`]'s), less the edges that the faces not kept leave in one
    /// face (a count that falls from 2 to 1); counted again over the kept faces when `link`
    /// did not run or an edge has too many faces for its count (255).
    fn interior(&mut self, faces: &[[i32; 3]], keep: &[bool]) -> Vec<u32> {
        match self.counted.take() {
            Some((mut count, mut interior)) if !count.contains(&u8::MAX) => {
                for (f, _) in faces.iter().zip(keep).filter(|(_, &k)| !k) {
                    for (a, b) in edges(f) {
                        let s = self.slot(a, b);
                        count[s] -= 1;
                        if count[s] == 1 {
                            interior[a as usize] -= 1;
                            interior[b as usize] -= 1;
                        }
                    }
                }
                interior
            }
            _ => self.interior_of_kept(faces, keep),
        }
    }

    /// [`GridEdges::interior`] counted over the kept faces alone.
    fn interior_of_kept(&self, faces: &[[i32; 3]], keep: &[bool]) -> Vec<u32> {
        let mut count = vec![0u8; 4 * self.pixel.len()];
        let mut interior = vec![0u32; self.pixel.len()];
        for (f, _) in faces.iter().zip(keep).filter(|(_, &k)| k) {
            for (a, b) in edges(f) {
                let s = self.slot(a, b);
                if count[s] < 2 {
                    count[s] += 1;
                    if count[s] == 2 {
                        interior[a as usize] += 1;
                        interior[b as usize] += 1;
                    }
                }
            }
        }
        interior
    }
}

/// Which faces share each edge: the grid's slots ([`GridEdges`]) or, for any mesh, the
/// edges bucketed ([`EdgeBuckets`]); both give the same links and interior edges.
enum EdgeTable<'a> {
    Grid(GridEdges<'a>),
    Buckets(EdgeBuckets),
}

impl EdgeTable<'_> {
    fn link(&mut self, faces: &[[i32; 3]], sets: &mut UnionFind) {
        match self {
            EdgeTable::Grid(t) => t.link(faces, sets),
            EdgeTable::Buckets(b) => b.link(sets),
        }
    }

    fn interior(&mut self, faces: &[[i32; 3]], keep: &[bool]) -> Vec<u32> {
        match self {
            EdgeTable::Grid(t) => t.interior(faces, keep),
            EdgeTable::Buckets(b) => b.interior(keep),
        }
    }
}

/// A face's three edges `(f0, f1)`, `(f1, f2)`, `(f2, f0)`.
fn edges(f: &[i32; 3]) -> [(i32, i32); 3] {
    [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])]
}

/// The faces of the grid mesh of an `H × W` grid (see `gnomon.geometry.meshing.grid_mesh`).
///
/// `valid`, `depth` (camera Z, f32, NaN where invalid) and `sigma` (σZ; NaN
/// counts as 0) are row-major `H·W`. Each 2×2 block of valid pixels `a b / c d`
/// is split along the diagonal whose ends are closer in depth (`|za − zd| ≤
/// |zb − zc|`: `a d`; with `b` or `c` missing `a d`, with `a` or `d` missing
/// `b c`), and a triangle is kept when its corners are finite and their depth
/// spread is at most `max(max_relative_jump · min Z, sigma_factor · max σ)`,
/// all in f32. Faces come in four groups, each in row-major block order:
/// `(a, c, d)`, `(a, d, b)` (split `a d`), `(a, c, b)`, `(b, c, d)` (split `b c`).
pub fn grid_faces(
    valid: &[u8],
    depth: &[f32],
    sigma: &[f32],
    width: usize,
    max_relative_jump: f32,
    sigma_factor: f32,
) -> Result<Vec<[i32; 3]>, KernelError> {
    let n = valid.len();
    KernelError::check_image(
        n,
        width,
        &[
            ("depth (one per pixel)", n, depth.len()),
            ("sigma (one per pixel)", n, sigma.len()),
        ],
    )?;
    if n > i32::MAX as usize {
        return Err(KernelError::parameter(
            "valid",
            "more pixels than an int32 index holds",
        ));
    }
    let height = n / width;
    let mut index = vec![-1i32; n];
    let mut next = 0i32;
    for (i, &v) in valid.iter().enumerate() {
        if v != 0 {
            index[i] = next;
            next += 1;
        }
    }
    let z = |i: usize| if valid[i] != 0 { depth[i] } else { f32::NAN };
    let s = |i: usize| {
        if valid[i] == 0 {
            0.0
        } else {
            let x = sigma[i];
            if x.is_nan() {
                0.0
            } else if x == f32::INFINITY {
                f32::MAX
            } else if x == f32::NEG_INFINITY {
                f32::MIN
            } else {
                x
            }
        }
    };
    let close = |p: [usize; 3]| {
        let zs = [z(p[0]), z(p[1]), z(p[2])];
        if !zs.iter().all(|v| v.is_finite()) {
            return false;
        }
        let lo = zs[0].min(zs[1]).min(zs[2]);
        let hi = zs[0].max(zs[1]).max(zs[2]);
        let smax = s(p[0]).max(s(p[1])).max(s(p[2]));
        let allowed = (max_relative_jump * lo).max(sigma_factor * smax);
        hi - lo <= allowed
    };
    let rows: Vec<usize> = (0..height.saturating_sub(1)).collect();
    let groups: Vec<[Vec<[i32; 3]>; 4]> = rows
        .par_chunks(ROWS_PER_TASK)
        .map(|chunk| {
            let mut out: [Vec<[i32; 3]>; 4] = Default::default();
            for &r in chunk {
                for c in 0..width - 1 {
                    let (a, b, cc, d) = (
                        r * width + c,
                        r * width + c + 1,
                        (r + 1) * width + c,
                        (r + 1) * width + c + 1,
                    );
                    let (za, zb, zc, zd) = (z(a), z(b), z(cc), z(d));
                    let mut split_ad = (za - zd).abs() <= (zb - zc).abs();
                    if zb.is_nan() || zc.is_nan() {
                        split_ad = true;
                    }
                    if za.is_nan() || zd.is_nan() {
                        split_ad = false;
                    }
                    let tri = |p: [usize; 3]| [index[p[0]], index[p[1]], index[p[2]]];
                    if split_ad {
                        if close([a, cc, d]) {
                            out[0].push(tri([a, cc, d]));
                        }
                        if close([a, d, b]) {
                            out[1].push(tri([a, d, b]));
                        }
                    } else {
                        if close([a, cc, b]) {
                            out[2].push(tri([a, cc, b]));
                        }
                        if close([b, cc, d]) {
                            out[3].push(tri([b, cc, d]));
                        }
                    }
                }
            }
            out
        })
        .collect();
    let total = groups
        .iter()
        .map(|g| g.iter().map(Vec::len).sum::<usize>())
        .sum();
    let mut faces = Vec::with_capacity(total);
    for k in 0..4 {
        for g in &groups {
            faces.extend_from_slice(&g[k]);
        }
    }
    Ok(faces)
}

/// `flat` (3·F vertex indices, row-major) as its F triangles, without a copy; an error when its
/// length is not a multiple of 3.
pub fn triangles(flat: &[i32]) -> Result<&[[i32; 3]], KernelError> {
    if flat.len() % 3 != 0 {
        return Err(KernelError::parameter(
            "faces",
            format!("{} vertex indices are not whole triangles", flat.len()),
        ));
    }
    // SAFETY: `[i32; 3]` is three `i32` with their alignment and no padding, so the
    // `flat.len() / 3` triangles cover exactly the values of `flat`, borrowed for as long.
    Ok(unsafe { std::slice::from_raw_parts(flat.as_ptr().cast::<[i32; 3]>(), flat.len() / 3) })
}

/// A cleaned mesh: `faces` into the new vertex list, `source[i]` the input
/// vertex that new vertex `i` copies.
#[derive(Debug, Clone, PartialEq)]
pub struct CleanMesh {
    pub faces: Vec<[i32; 3]>,
    pub source: Vec<i64>,
}

/// Drop edge-connected pieces with fewer than `min_vertices` vertices, then
/// give every fan of triangles meeting at a vertex only there its own copy of
/// the vertex (see `gnomon.geometry.meshing.remove_small_components` and
/// `split_non_manifold_vertices`, whose results these are, element for element).
///
/// A piece's size counts each vertex once, for the piece of the last face (in
/// order) that uses it. Vertices in no kept face are dropped; the kept ones
/// keep their order, and the copies follow, in order of their fan's first
/// corner (faces in order, corners in order).
pub fn clean_faces(
    n_vertices: usize,
    faces: &[[i32; 3]],
    min_vertices: usize,
) -> Result<CleanMesh, KernelError> {
    clean_grid_faces(n_vertices, faces, min_vertices, None)
}

/// [`clean_faces`], the same result, with the pixel grid the vertices lie on (`grid`): when
/// every edge is a grid step (a mesh of `grid_faces`) the faces sharing an edge are found
/// through the edge's grid slot instead of bucketing the edges; otherwise as without it.
/// An error when `grid`'s pixels are not one per vertex.
pub fn clean_grid_faces(
    n_vertices: usize,
    faces: &[[i32; 3]],
    min_vertices: usize,
    grid: Option<VertexPixels>,
) -> Result<CleanMesh, KernelError> {
    if faces
        .as_flattened()
        .par_iter()
        .any(|&v| v < 0 || v as usize >= n_vertices)
    {
        return Err(KernelError::parameter(
            "faces",
            format!("index a vertex outside 0..{n_vertices}"),
        ));
    }
    if faces.len() * 3 > u32::MAX as usize {
        return Err(KernelError::parameter(
            "faces",
            "more corners than a u32 index holds",
        ));
    }
    if let Some(g) = grid {
        if g.pixel.len() != n_vertices {
            return Err(KernelError::LengthMismatch {
                what: "pixels (one per vertex)",
                expected: n_vertices,
                got: g.pixel.len(),
            });
        }
    }
    // Pieces: faces sharing an edge.
    let mut table = match grid.and_then(|g| GridEdges::new(g, faces)) {
        Some(t) => EdgeTable::Grid(t),
        None => EdgeTable::Buckets(EdgeBuckets::new(n_vertices, faces)),
    };
    let mut sets = UnionFind::new(faces.len());
    table.link(faces, &mut sets);
    let root = sets.into_roots();
    let mut vertex_piece = vec![u32::MAX; n_vertices];
    // Each vertex's faces (< 2^32: at most 3·faces), all of them here, the kept ones below.
    let mut degree = vec![0u32; n_vertices];
    for (f, &r) in faces.iter().zip(&root) {
        for &v in f {
            vertex_piece[v as usize] = r;
            degree[v as usize] += 1;
        }
    }
    // A piece's vertices, at most `n_vertices` (< 2^31: they are i32 indices).
    let mut size = vec![0u32; faces.len()];
    for &r in vertex_piece.iter().filter(|&&r| r != u32::MAX) {
        size[r as usize] += 1;
    }
    drop(vertex_piece);
    let keep: Vec<bool> = root
        .iter()
        .map(|&r| size[r as usize] as usize >= min_vertices)
        .collect();
    drop((root, size));
    for (f, _) in faces.iter().zip(&keep).filter(|(_, &k)| !k) {
        for &v in f {
            degree[v as usize] -= 1;
        }
    }
    let interior = table.interior(faces, &keep);
    drop(table);
    Ok(split_fans(faces, &keep, &interior, degree))
}

/// The faces `keep` marks, renumbered, with every fan of triangles at a vertex beyond its first
/// given its own copy of the vertex (see [`clean_faces`]); `interior[v]`: the edges at `v` in two
/// or more of the kept faces; `degree[v]`: the kept faces at `v` (one per vertex).
///
/// Invariant: vertex indices of `faces` are in `0..degree.len()` (the vertices). The kept vertices are numbered
/// in their order (a monotonic renumbering, so edges compare equal before and after it).
fn split_fans(faces: &[[i32; 3]], keep: &[bool], interior: &[u32], degree: Vec<u32>) -> CleanMesh {
    let n_vertices = degree.len();
    let mut remap = vec![-1i32; n_vertices];
    let used = degree.iter().filter(|&&d| d > 0).count();
    let mut source: Vec<i64> = Vec::with_capacity(used);
    // A vertex with two or more open fans has more faces than interior edges plus one.
    let mut several_fans: Vec<bool> = Vec::with_capacity(used);
    for (v, &d) in degree.iter().enumerate() {
        if d > 0 {
            remap[v] = source.len() as i32;
            source.push(v as i64);
            several_fans.push(i64::from(d) - i64::from(interior[v]) >= 2);
        }
    }
    drop(degree);
    // Into one vector of the exact length (a parallel filter collects pieces, then copies them).
    let mut out: Vec<[i32; 3]> = Vec::with_capacity(keep.iter().filter(|&&k| k).count());
    out.extend(
        faces
            .iter()
            .zip(keep)
            .filter(|(_, &k)| k)
            .map(|(f, _)| f.map(|v| remap[v as usize])),
    );
    drop(remap);
    let corners: Vec<usize> = (0..3 * out.len())
        .into_par_iter()
        .filter(|&c| several_fans[out[c / 3][c % 3] as usize])
        .collect();
    if !corners.is_empty() {
        // Fans: corners at one vertex whose triangles share an edge at it.
        // Directed edges (v → next, v → previous) of the corners, sorted: equal ones link corners.
        let n = source.len() as u64;
        let mut sets = UnionFind::new(corners.len());
        let mut pairs: Vec<(u64, u32)> = Vec::with_capacity(2 * corners.len());
        for (k, &c) in corners.iter().enumerate() {
            let (face, pos) = (out[c / 3], c % 3);
            let v = face[pos] as u64;
            pairs.push((v * n + face[(pos + 1) % 3] as u64, k as u32));
            pairs.push((v * n + face[(pos + 2) % 3] as u64, k as u32));
        }
        pairs.par_sort_unstable_by_key(|p| p.0);
        for w in pairs.windows(2) {
            if w[0].0 == w[1].0 {
                sets.union(w[0].1, w[1].1);
            }
        }
        // Fan labels in order of their first corner; the first fan at a vertex keeps it.
        let mut label = vec![u32::MAX; corners.len()];
        let mut fan_vertex: Vec<i32> = Vec::new();
        for (k, &c) in corners.iter().enumerate() {
            let r = sets.find(k as u32) as usize;
            if label[r] == u32::MAX {
                label[r] = fan_vertex.len() as u32;
                fan_vertex.push(out[c / 3][c % 3]);
            }
        }
        let mut first_fan = vec![u32::MAX; source.len()];
        let mut fan_new = vec![0i32; fan_vertex.len()];
        for (f, &v) in fan_vertex.iter().enumerate() {
            if first_fan[v as usize] == u32::MAX {
                first_fan[v as usize] = f as u32;
                fan_new[f] = v;
            }
        }
        for (f, &v) in fan_vertex.iter().enumerate() {
            if first_fan[v as usize] != f as u32 {
                fan_new[f] = source.len() as i32;
                source.push(source[v as usize]);
            }
        }
        for (k, &c) in corners.iter().enumerate() {
            let r = sets.find(k as u32) as usize;
            out[c / 3][c % 3] = fan_new[label[r] as usize];
        }
    }
    CleanMesh { faces: out, source }
}

/// Decimal digits of `x` (at least one).
fn digits(mut x: u64) -> usize {
    let mut d = 1;
    while x >= 10 {
        x /= 10;
        d += 1;
    }
    d
}

/// One column of fixed-point numbers: `values[i·stride + offset]`, `decimals` decimals, and the
/// width of its widest integer part.
struct Column<'a> {
    values: &'a [f64],
    stride: usize,
    offset: usize,
    decimals: usize,
    scale: u64,
    int_digits: usize,
}

impl<'a> Column<'a> {
    fn new(values: &'a [f64], stride: usize, offset: usize, decimals: usize) -> Column<'a> {
        let scale = 10u64.pow(decimals as u32);
        let mut column = Column {
            values,
            stride,
            offset,
            decimals,
            scale,
            int_digits: 1,
        };
        let top = values
            .par_chunks(stride)
            .map(|row| column.quantise(row[offset]).1)
            .max()
            .unwrap_or(0);
        column.int_digits = digits(top);
        column
    }

    /// `(negative, integer part, fraction)` of `x`: NaN and ±inf as 0, rounded half to even at `decimals`.
    fn quantise(&self, x: f64) -> (bool, u64, u64) {
        let x = if x.is_finite() { x } else { 0.0 };
        let q = (x.abs() * self.scale as f64).round_ties_even() as u64;
        (x < 0.0 && q > 0, q / self.scale, q % self.scale)
    }

    /// Bytes of one field: `" "` + a place for the sign + the integer part + (`"."` + fraction, or `" "`).
    fn width(&self) -> usize {
        1 + 1
            + self.int_digits
            + if self.decimals > 0 {
                1 + self.decimals
            } else {
                1
            }
    }

    /// Row `i`'s field into `out` (`width()` bytes): `" "`, the right-aligned `"[-]int"` in
    /// `int_digits + 1` places, then `"." + fraction` (or `" "` without decimals).
    fn write(&self, i: usize, out: &mut [u8]) {
        let (neg, mut ip, mut fp) = self.quantise(self.values[i * self.stride + self.offset]);
        let mut k = out.len();
        if self.decimals > 0 {
            for _ in 0..self.decimals {
                k -= 1;
                out[k] = b'0' + (fp % 10) as u8;
                fp /= 10;
            }
            k -= 1;
            out[k] = b'.';
        } else {
            k -= 1;
            out[k] = b' ';
        }
        loop {
            k -= 1;
            out[k] = b'0' + (ip % 10) as u8;
            ip /= 10;
            if ip == 0 {
                break;
            }
        }
        if neg {
            k -= 1;
            out[k] = b'-';
        }
        out[..k].fill(b' ');
    }
}

fn write_uint(x: u64, out: &mut Vec<u8>) {
    let mut buf = [0u8; 20];
    let mut k = buf.len();
    let mut rest = x;
    loop {
        k -= 1;
        buf[k] = b'0' + (rest % 10) as u8;
        rest /= 10;
        if rest == 0 {
            break;
        }
    }
    out.extend_from_slice(&buf[k..]);
}

/// Lines `prefix col col …\n` for the rows of `columns`: every line has the same width, so the rows
/// are formatted in parallel straight into one buffer.
fn column_lines(prefix: &[u8], columns: &[Column], rows: usize) -> Vec<Vec<u8>> {
    let line = prefix.len() + columns.iter().map(Column::width).sum::<usize>() + 1;
    let mut out = vec![0u8; rows * line];
    out.par_chunks_mut(line * ITEMS_PER_TASK)
        .enumerate()
        .for_each(|(task, block)| {
            for (r, text) in block.chunks_exact_mut(line).enumerate() {
                let i = task * ITEMS_PER_TASK + r;
                text[..prefix.len()].copy_from_slice(prefix);
                let mut at = prefix.len();
                for c in columns {
                    let w = c.width();
                    c.write(i, &mut text[at..at + w]);
                    at += w;
                }
                text[at] = b'\n';
            }
        });
    vec![out]
}

/// The body of a Wavefront OBJ file (see `gnomon.outputs.obj.write_obj`, whose text this is, byte for byte).
///
/// `vertices` `V·3` (`v` lines, `vertex_decimals` decimals), `uv` `V·2`
/// (`vt`, 6 decimals), `normals` `V·3` (`vn`, 5 decimals), `faces` `F·3`
/// 0-based (`f a/a/a` with the 1-based index once per attribute present).
/// Each column is right-aligned to its widest integer part, with one place
/// for a minus sign; NaN and ±inf are written as 0.
pub fn obj_text(
    vertices: &[f64],
    vertex_decimals: usize,
    uv: Option<&[f64]>,
    normals: Option<&[f64]>,
    faces: &[i64],
) -> Result<Vec<u8>, KernelError> {
    Ok(obj_text_parts(vertices, vertex_decimals, uv, normals, faces)?.concat())
}

/// [`obj_text`] as consecutive buffers (blocks of lines), without joining them.
pub fn obj_text_parts(
    vertices: &[f64],
    vertex_decimals: usize,
    uv: Option<&[f64]>,
    normals: Option<&[f64]>,
    faces: &[i64],
) -> Result<Vec<Vec<u8>>, KernelError> {
    if vertices.len() % 3 != 0 {
        return Err(KernelError::parameter(
            "vertices",
            "expected rows of 3 coordinates",
        ));
    }
    if vertex_decimals > 15 {
        return Err(KernelError::parameter("vertex_decimals", "at most 15"));
    }
    let nv = vertices.len() / 3;
    for (what, arr, k) in [
        ("uv (2 per vertex)", uv, 2usize),
        ("normals (3 per vertex)", normals, 3),
    ] {
        if let Some(a) = arr {
            if a.len() != k * nv {
                return Err(KernelError::LengthMismatch {
                    what,
                    expected: k * nv,
                    got: a.len(),
                });
            }
        }
    }
    if faces.len() % 3 != 0 || faces.iter().any(|&f| f < 0 || f as usize >= nv) {
        return Err(KernelError::parameter(
            "faces",
            "expected rows of 3 vertex indices in range",
        ));
    }
    let mut out: Vec<Vec<u8>> = Vec::new();
    if nv > 0 {
        fn cols(a: &[f64], k: usize, dec: usize) -> Vec<Column<'_>> {
            (0..k).map(|j| Column::new(a, k, j, dec)).collect()
        }
        out.extend(column_lines(b"v", &cols(vertices, 3, vertex_decimals), nv));
        if let Some(t) = uv {
            out.extend(column_lines(b"vt", &cols(t, 2, 6), nv));
        }
        if let Some(nrm) = normals {
            out.extend(column_lines(b"vn", &cols(nrm, 3, 5), nv));
        }
    }
    // One token per vertex ("a", "a/a" with texture, "a//a" with normals, "a/a/a" with both), gathered by the faces.
    let (with_uv, with_normals) = (uv.is_some(), normals.is_some());
    let width = 3 * (digits(nv as u64) + 2);
    let tokens: Vec<(usize, [u8; 64])> = (0..nv)
        .into_par_iter()
        .map(|i| {
            let mut t = Vec::with_capacity(width);
            let idx = i as u64 + 1;
            write_uint(idx, &mut t);
            if with_uv {
                t.push(b'/');
                write_uint(idx, &mut t);
            }
            if with_normals {
                t.extend_from_slice(if with_uv { b"/" } else { b"//" });
                write_uint(idx, &mut t);
            }
            let mut fixed = [0u8; 64];
            fixed[..t.len()].copy_from_slice(&t);
            (t.len(), fixed)
        })
        .collect();
    let chunks: Vec<Vec<u8>> = faces
        .par_chunks(3 * ITEMS_PER_TASK)
        .map(|chunk| {
            let mut o = Vec::with_capacity(chunk.len() / 3 * (3 * width + 5));
            for f in chunk.chunks_exact(3) {
                o.push(b'f');
                for &v in f {
                    o.push(b' ');
                    let (len, ref bytes) = tokens[v as usize];
                    o.extend_from_slice(&bytes[..len]);
                }
                o.push(b'\n');
            }
            o
        })
        .collect();
    out.extend(chunks);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_grid_is_two_triangles_per_block_and_clean() {
        let (h, w) = (4, 5);
        let valid = vec![1u8; h * w];
        let depth = vec![100.0f32; h * w];
        let sigma = vec![0.1f32; h * w];
        let faces = grid_faces(&valid, &depth, &sigma, w, 0.05, 5.0).unwrap();
        assert_eq!(faces.len(), 2 * (h - 1) * (w - 1));
        // equal depths split along a–d: group (a, c, d) first
        assert_eq!(faces[0], [0, w as i32, w as i32 + 1]);
        let clean = clean_faces(h * w, &faces, 3).unwrap();
        assert_eq!(clean.faces, faces);
        assert_eq!(clean.source, (0..(h * w) as i64).collect::<Vec<_>>());
    }

    #[test]
    fn depth_jump_cuts_and_small_pieces_go() {
        let (h, w) = (3, 6);
        let valid = vec![1u8; h * w];
        let depth: Vec<f32> = (0..h * w)
            .map(|i| if i % w < 3 { 100.0 } else { 200.0 })
            .collect();
        let faces = grid_faces(&valid, &depth, &vec![0.0; h * w], w, 0.05, 5.0).unwrap();
        // two 3×3 pieces of 8 faces each; no face bridges columns 2 and 3
        assert_eq!(faces.len(), 16);
        assert!(faces
            .iter()
            .all(|f| f.iter().all(|&v| v % 6 < 3) || f.iter().all(|&v| v % 6 >= 3)));
        assert_eq!(clean_faces(h * w, &faces, 10).unwrap().faces.len(), 0);
        assert_eq!(clean_faces(h * w, &faces, 9).unwrap().faces.len(), 16);
    }

    /// A deterministic pseudo-random sequence (a 64-bit LCG's high bits), for test meshes.
    fn lcg(seed: u64) -> impl FnMut(u32) -> u32 {
        let mut state = seed;
        move |below| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 33) % u64::from(below)) as u32
        }
    }

    fn random_faces(n_vertices: u32, n_faces: usize, seed: u64) -> Vec<[i32; 3]> {
        let mut next = lcg(seed);
        (0..n_faces)
            .map(|_| [0; 3].map(|_: i32| next(n_vertices) as i32))
            .collect()
    }

    #[test]
    fn edge_buckets_are_the_counting_sort_with_a_separate_cursor() {
        for seed in 0..4 {
            let n = 40;
            let faces = random_faces(n as u32, 150, seed);
            let buckets = EdgeBuckets::new(n, &faces);
            // the definition: bucket starts by counting, a copy of them as the fill cursors
            let edges = |f: &[i32; 3]| [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])];
            let mut start = vec![0u32; n + 1];
            for f in &faces {
                for (a, b) in edges(f) {
                    start[a.min(b) as usize + 1] += 1;
                }
            }
            for i in 0..n {
                start[i + 1] += start[i];
            }
            let mut fill = start.clone();
            let mut slot = vec![(0u32, 0u32); 3 * faces.len()];
            for (i, f) in faces.iter().enumerate() {
                for (a, b) in edges(f) {
                    let lo = a.min(b) as usize;
                    slot[fill[lo] as usize] = (a.max(b) as u32, i as u32);
                    fill[lo] += 1;
                }
            }
            assert_eq!(buckets.start, start);
            assert_eq!(buckets.slot, slot);
        }
    }

    #[test]
    fn roots_in_place_are_each_elements_find() {
        let mut next = lcg(7);
        let mut sets = UnionFind::new(200);
        for _ in 0..150 {
            let (a, b) = (next(200), next(200));
            sets.union(a, b);
        }
        let mut reference = sets.parent.clone();
        let mut copy = UnionFind {
            parent: std::mem::take(&mut reference),
        };
        let expected: Vec<u32> = (0..200).map(|i| copy.find(i)).collect();
        assert_eq!(sets.into_roots(), expected);
    }

    #[test]
    fn triangles_view_the_flat_indices_in_place() {
        let flat: Vec<i32> = (0..12).collect();
        let tris = triangles(&flat).unwrap();
        let copied: Vec<[i32; 3]> = flat.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        assert_eq!(tris, copied.as_slice());
        assert_eq!(tris.as_ptr().cast::<i32>(), flat.as_ptr());
        assert!(triangles(&flat[..11]).is_err());
        assert!(triangles(&[]).unwrap().is_empty());
    }

    #[test]
    fn random_meshes_clean_like_the_copying_version() {
        // pieces' sizes, kept faces and split fans against a build that keeps every step's copy
        for (seed, min_vertices) in [(1, 1), (2, 3), (3, 5), (4, 8)] {
            let n = 60;
            let faces = random_faces(n as u32, 90, seed);
            let clean = clean_faces(n, &faces, min_vertices).unwrap();
            let buckets = EdgeBuckets::new(n, &faces);
            let mut sets = UnionFind::new(faces.len());
            buckets.link(&mut sets);
            let root: Vec<u32> = (0..faces.len() as u32).map(|i| sets.find(i)).collect();
            let mut vertex_piece = vec![u32::MAX; n];
            for (f, &r) in faces.iter().zip(&root) {
                for &v in f {
                    vertex_piece[v as usize] = r;
                }
            }
            let mut size = vec![0usize; faces.len()];
            for &r in vertex_piece.iter().filter(|&&r| r != u32::MAX) {
                size[r as usize] += 1;
            }
            let keep: Vec<bool> = root
                .iter()
                .map(|&r| size[r as usize] >= min_vertices)
                .collect();
            let mut degree = vec![0u32; n];
            for (f, _) in faces.iter().zip(&keep).filter(|(_, &k)| k) {
                for &v in f {
                    degree[v as usize] += 1;
                }
            }
            let expected = split_fans(&faces, &keep, &buckets.interior(&keep), degree);
            assert_eq!(clean, expected);
            assert_eq!(clean.faces.len(), keep.iter().filter(|&&k| k).count());
        }
    }

    /// A random grid mesh: `h × w` pixels, about a tenth invalid, depths in steps that the
    /// jump test cuts, and the valid pixels (row-major) as the vertices' pixels.
    fn random_grid_mesh(h: usize, w: usize, seed: u64) -> (Vec<[i32; 3]>, Vec<i64>) {
        let mut next = lcg(seed);
        let valid: Vec<u8> = (0..h * w).map(|_| u8::from(next(10) != 0)).collect();
        let depth: Vec<f32> = (0..h * w).map(|_| 100.0 + 20.0 * next(3) as f32).collect();
        let faces = grid_faces(&valid, &depth, &vec![0.0; h * w], w, 0.05, 5.0).unwrap();
        let pixel = (0..(h * w) as i64)
            .filter(|&p| valid[p as usize] != 0)
            .collect();
        (faces, pixel)
    }

    #[test]
    fn grid_slots_clean_like_the_buckets() {
        let (mut dropped, mut split) = (false, false);
        for (seed, (h, w), min_vertices) in [
            (1, (9, 7), 1),
            (2, (12, 11), 4),
            (3, (20, 3), 3),
            (4, (15, 16), 6),
        ] {
            let (faces, pixel) = random_grid_mesh(h, w, seed);
            let n = pixel.len();
            let grid = VertexPixels {
                pixel: &pixel,
                width: w,
            };
            assert!(GridEdges::new(grid, &faces).is_some());
            let expected = clean_faces(n, &faces, min_vertices).unwrap();
            assert!(!expected.faces.is_empty());
            dropped |= expected.faces.len() < faces.len();
            split |= expected.source.len()
                > expected
                    .source
                    .iter()
                    .collect::<std::collections::HashSet<_>>()
                    .len();
            assert_eq!(
                clean_grid_faces(n, &faces, min_vertices, Some(grid)).unwrap(),
                expected
            );
        }
        // the meshes had small pieces to drop and vertices to split
        assert!(dropped && split);
    }

    #[test]
    fn grid_slots_are_the_buckets_links_and_interior_edges() {
        let (faces, pixel) = random_grid_mesh(14, 13, 9);
        let n = pixel.len();
        let mut table = GridEdges::new(
            VertexPixels {
                pixel: &pixel,
                width: 13,
            },
            &faces,
        )
        .unwrap();
        let buckets = EdgeBuckets::new(n, &faces);
        let (mut by_grid, mut by_buckets) =
            (UnionFind::new(faces.len()), UnionFind::new(faces.len()));
        table.link(&faces, &mut by_grid);
        buckets.link(&mut by_buckets);
        // the same partition: each face's root is the same face under both
        let (a, b) = (by_grid.into_roots(), by_buckets.into_roots());
        for i in 0..faces.len() {
            for j in 0..faces.len() {
                assert_eq!(a[i] == a[j], b[i] == b[j]);
            }
        }
        let mut next = lcg(5);
        let keep: Vec<bool> = faces.iter().map(|_| next(4) != 0).collect();
        // from link's counts less the dropped faces', and counted over the kept faces alone
        assert_eq!(
            table.interior_of_kept(&faces, &keep),
            buckets.interior(&keep)
        );
        assert_eq!(table.interior(&faces, &keep), buckets.interior(&keep));
        assert!(table.counted.is_none());
        assert_eq!(table.interior(&faces, &keep), buckets.interior(&keep));
    }

    #[test]
    fn an_edge_of_many_faces_is_counted_over_the_kept_faces() {
        // one triangle repeated 300 times (its edges' counts saturate) beside another, four
        // vertices, and a piece of three to drop
        let (w, pixel): (usize, Vec<i64>) = (5, (0..25).collect());
        let mut faces = vec![[0, 5, 6]; 300];
        faces.push([0, 6, 1]);
        faces.push([12, 17, 18]);
        let grid = VertexPixels {
            pixel: &pixel,
            width: w,
        };
        let clean = clean_grid_faces(25, &faces, 3, Some(grid)).unwrap();
        assert_eq!(clean, clean_faces(25, &faces, 3).unwrap());
        assert_eq!(clean.faces.len(), 302);
        let fewer = clean_grid_faces(25, &faces, 4, Some(grid)).unwrap();
        assert_eq!(fewer, clean_faces(25, &faces, 4).unwrap());
        assert_eq!(fewer.faces.len(), 301);
    }

    #[test]
    fn off_grid_edges_fall_back_to_the_buckets() {
        let (mut faces, pixel) = random_grid_mesh(10, 9, 3);
        let n = pixel.len();
        let grid = VertexPixels {
            pixel: &pixel,
            width: 9,
        };
        // a face between far pixels; pixels out of order; a grid 2 wide (its steps 1 and W − 1 agree)
        faces.push([0, (n / 2) as i32, (n - 1) as i32]);
        assert!(GridEdges::new(grid, &faces).is_none());
        assert_eq!(
            clean_grid_faces(n, &faces, 3, Some(grid)).unwrap(),
            clean_faces(n, &faces, 3).unwrap()
        );
        faces.pop();
        let mut shuffled = pixel.clone();
        shuffled.swap(3, 4);
        assert!(GridEdges::new(
            VertexPixels {
                pixel: &shuffled,
                width: 9
            },
            &faces
        )
        .is_none());
        assert!(GridEdges::new(
            VertexPixels {
                pixel: &pixel,
                width: 2
            },
            &faces
        )
        .is_none());
        assert!(clean_grid_faces(
            n,
            &faces,
            3,
            Some(VertexPixels {
                pixel: &pixel[1..],
                width: 9
            })
        )
        .is_err());
    }

    #[test]
    fn bow_tie_vertex_is_split() {
        // two triangles touching only at vertex 2
        let faces = vec![[0, 1, 2], [2, 3, 4]];
        let clean = clean_faces(5, &faces, 1).unwrap();
        assert_eq!(clean.source, vec![0, 1, 2, 3, 4, 2]);
        assert_eq!(clean.faces, vec![[0, 1, 2], [5, 3, 4]]);
    }

    #[test]
    fn obj_columns_are_aligned_and_rounded_half_to_even() {
        let v = [1.5, -0.25, 12.0, -0.0001, 3.0, f64::NAN];
        let text = obj_text(&v, 2, None, None, &[0, 1, 0]).unwrap();
        assert_eq!(
            String::from_utf8(text).unwrap(),
            "v  1.50 -0.25  12.00\nv  0.00  3.00   0.00\nf 1 2 1\n"
        );
    }

    #[test]
    fn bad_indices_are_errors() {
        assert!(clean_faces(2, &[[0, 1, 2]], 1).is_err());
        assert!(obj_text(&[0.0; 3], 2, None, None, &[0, 0, 1]).is_err());
        assert!(grid_faces(&[1; 6], &[0.0; 5], &[0.0; 6], 3, 0.1, 5.0).is_err());
    }
}
