"""Wavefront OBJ: a mesh with its material (``.mtl``) and texture image (``.png``).

Texture coordinates come from each vertex's pixel; the text is formatted by the kernel
(``_kernel.obj_text``, equal to :func:`_obj_body_numpy`) with array operations only (no per-vertex
Python loop). :func:`write_scan_obj` is the scan's ``obj`` mesh format (:mod:`gnomon.outputs.formats`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from gnomon import __version__, _kernel
from gnomon.geometry.surface import Surface
from gnomon.util import atomic

__all__ = ["write_obj", "write_scan_obj", "write_texture"]


def _int_chars(values: np.ndarray) -> np.ndarray:
    """(N, D) uint8 decimal digits of non-negative ints, right-aligned, NUL-padded."""
    x = np.asarray(values, dtype=np.int64).ravel()
    d = max(1, len(str(int(x.max())))) if x.size else 1
    out = np.zeros((x.size, d), dtype=np.uint8)
    rest = x.copy()
    for j in range(d - 1, -1, -1):
        rest, digit = np.divmod(rest, 10)
        out[:, j] = digit + 48
        if j < d - 1:
            out[:, j][(rest == 0) & (digit == 0)] = 0  # leading zeros
    return out


def _fixed_chars(values: np.ndarray, decimals: int) -> np.ndarray:
    """(N, W) uint8 fixed-point text of floats, right-aligned, space-padded (``-12.3400``).

    NaN and inf are written as 0 (an OBJ file has no way to say "none").
    """
    x = np.nan_to_num(np.asarray(values, dtype=np.float64).ravel(), nan=0.0, posinf=0.0, neginf=0.0)
    scale = 10 ** decimals
    q = np.rint(np.abs(x) * scale).astype(np.int64)
    neg = (x < 0) & (q > 0)
    ip, fp = np.divmod(q, scale)
    ichars = _int_chars(ip)
    ichars[:, -1][ichars[:, -1] == 0] = 48
    n, di = ichars.shape
    out = np.full((n, 1 + di + 1 + decimals), 32, dtype=np.uint8)
    body = out[:, 1:1 + di]
    body[:] = np.where(ichars == 0, 32, ichars)
    # the minus sign goes right before the first digit
    first = np.argmax(ichars != 0, axis=1)
    rows = np.flatnonzero(neg)
    out[rows, first[rows]] = ord("-")
    if decimals:
        out[:, 1 + di] = ord(".")
        for j in range(decimals):
            out[:, 2 + di + j] = (fp // 10 ** (decimals - 1 - j)) % 10 + 48
    return out


def _decimals_for(values: np.ndarray, significant: int = 8) -> int:
    """Decimals that keep ``significant`` digits of the largest magnitude (float32 holds ~7.2)."""
    finite = np.abs(values[np.isfinite(values)])
    top = float(finite.max()) if finite.size else 1.0
    digits = len(str(int(top))) if top >= 1 else 0
    return int(np.clip(significant - digits, 1, 9))


def _lines(prefix: bytes, columns: list[np.ndarray]) -> bytes:
    """Join per-row byte columns into lines ``prefix col col ...\\n`` (space-padded columns)."""
    n = columns[0].shape[0]
    width = len(prefix) + sum(c.shape[1] + 1 for c in columns) + 1
    buf = np.empty((n, width), dtype=np.uint8)
    buf[:, :len(prefix)] = np.frombuffer(prefix, dtype=np.uint8)
    o = len(prefix)
    for c in columns:
        buf[:, o] = 32
        buf[:, o + 1:o + 1 + c.shape[1]] = c
        o += 1 + c.shape[1]
    buf[:, o] = 10
    return buf.tobytes()


def write_obj(path: str | os.PathLike, vertices: np.ndarray, faces: np.ndarray, *,
              normals: np.ndarray | None = None, uv: np.ndarray | None = None,
              texture: np.ndarray | None = None, comment: str = "") -> None:
    """Write a triangle mesh as Wavefront OBJ, atomically, with its material and texture.

    ``vertices`` (V, 3) world units; ``faces`` (F, 3) 0-based; ``normals``
    (V, 3) unit vectors (``vn``); ``uv`` (V, 2) texture coordinates in [0, 1]
    (``vt``, origin bottom-left as OBJ wants); ``texture`` (H, W, 3) uint8 RGB:
    written as ``<stem>.png`` beside the OBJ with a material file
    ``<stem>.mtl`` (``map_Kd``) that the OBJ names in ``mtllib``. Faces refer
    to the same index for position, texture and normal (``f a/a/a``).
    Only official OBJ statements are used (no per-vertex colours).
    """

    target = Path(path)
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError("faces index vertices out of range")
    parts: list[bytes | np.ndarray] = [f"# gnomon mesh: {len(v)} vertices, {len(f)} faces\n".encode()]
    if comment:
        parts += [f"# {line}\n".encode() for line in comment.splitlines()]
    if texture is not None:
        if uv is None:
            raise ValueError("a texture needs texture coordinates (uv)")
        parts.append(f"mtllib {target.stem}.mtl\nusemtl gnomon\n".encode())
    if len(v) or len(f):
        t = None if uv is None else np.ascontiguousarray(uv, dtype=np.float64).reshape(len(v), 2)
        n = None if normals is None else np.ascontiguousarray(normals, dtype=np.float64).reshape(len(v), 3)
        args = (np.ascontiguousarray(v), _decimals_for(v) if len(v) else 1, t, n, np.ascontiguousarray(f))
        # the text's blocks as arrays the kernel filled (written one after the other, never joined)
        parts.extend(_kernel.obj_text(*args, as_parts=True))
    _write_obj_material(target, texture)
    atomic.write_parts(target, parts)


def _obj_body_numpy(v: np.ndarray, f: np.ndarray, uv: np.ndarray | None, normals: np.ndarray | None) -> bytes:
    """write_obj's v/vt/vn/f lines in numpy (the kernel's ``obj_text`` gives the same bytes)."""
    parts: list[bytes] = []
    if len(v):
        dec = _decimals_for(v)
        parts.append(_lines(b"v", [_fixed_chars(v[:, k], dec) for k in range(3)]))
        if uv is not None:
            t = np.asarray(uv, dtype=np.float64).reshape(len(v), 2)
            parts.append(_lines(b"vt", [_fixed_chars(t[:, k], 6) for k in range(2)]))
        if normals is not None:
            n = np.asarray(normals, dtype=np.float64).reshape(len(v), 3)
            parts.append(_lines(b"vn", [_fixed_chars(n[:, k], 5) for k in range(3)]))
    if len(f):
        # One token per vertex ("12/12/12", NUL-padded: removed below), gathered by the faces.
        idx = _int_chars(np.arange(1, len(v) + 1))
        k = 1 + (uv is not None) + (normals is not None)
        d = idx.shape[1]
        token = np.zeros((len(idx), k * d + (k - 1)), dtype=np.uint8)
        for j in range(k):
            token[:, j * (d + 1):j * (d + 1) + d] = idx
            if j:
                token[:, j * (d + 1) - 1] = ord("/")
        if uv is None and normals is not None:  # position//normal
            token = np.concatenate([token[:, :d + 1], np.full((len(idx), 1), ord("/"), np.uint8),
                                    token[:, d + 1:]], axis=1)
        buf = _lines(b"f", [token[f[:, j]] for j in range(3)])
        arr = np.frombuffer(buf, dtype=np.uint8)
        parts.append(arr[arr != 0].tobytes())
    return b"".join(parts)


def _write_obj_material(target: Path, texture: np.ndarray | None) -> None:
    """``<stem>.png`` (the texture) and ``<stem>.mtl`` beside an OBJ file."""
    if texture is not None:
        write_texture(target.with_suffix(".png"), texture)
        atomic.write_text(target.with_suffix(".mtl"),
                          "# gnomon material: the scan's colours as a texture\n"
                          "newmtl gnomon\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1\n"
                          f"map_Kd {target.stem}.png\n")


def write_texture(path: str | os.PathLike, texture: np.ndarray) -> None:
    """The colour image (H, W, 3) uint8 RGB (or (H, W) grey) as a PNG, atomically (an OBJ's texture)."""
    import cv2

    img = np.asarray(texture, dtype=np.uint8)
    ok, png = cv2.imencode(".png", img[:, :, ::-1] if img.ndim == 3 else img)
    if not ok:  # pragma: no cover
        raise RuntimeError("PNG encoding failed")
    atomic.write_bytes(path, png.tobytes())




def write_scan_obj(folder: Path, surface: Surface, units: str) -> None:
    """mesh.obj, mesh.mtl and mesh.png: the surface's mesh with the colour image as its texture."""
    mesh = surface.mesh
    h, w = surface.valid.shape
    tex_uv = (mesh.pixel_uv(w) + 0.5) / np.array([w, h], dtype=np.float32)
    tex_uv[:, 1] = 1.0 - tex_uv[:, 1]  # OBJ: v up from the image's bottom
    write_obj(folder / "mesh.obj", mesh.vertices, mesh.faces, normals=mesh.normals, uv=tex_uv,
              texture=surface.rgb, comment=f"gnomon {__version__}, units {units}, frame world")
