"""PLY writer/reader: layout, bit-for-bit round trips, atomic writes, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from gnomon.errors import GnomonError
from gnomon.outputs.ply import read_ply, units_comment, write_mesh_ply, write_points_ply


def _cloud(n: int = 1000, seed: int = 0):
    rng = np.random.default_rng(seed)
    xyz = (rng.normal(size=(n, 3)) * 123.456).astype(np.float32)
    # Values whose bits a careless text or float64 round trip would change.
    xyz[0] = [np.float32(0.1), np.float32(-0.0), np.float32(1e-42)]  # 1e-42: a float32 subnormal
    xyz[1] = [np.float32(np.pi), np.float32(3.4e38), np.float32(-1.17549435e-38)]
    rgb = rng.integers(0, 256, size=(n, 3), dtype=np.uint8)
    sigma = rng.random(n).astype(np.float32)
    uv = (rng.random((n, 2)) * [1919, 1079]).astype(np.float32)
    return xyz, rgb, sigma, uv


def _header(path) -> list[str]:
    raw = path.read_bytes()
    return raw[: raw.index(b"end_header")].decode("ascii").splitlines()


def test_points_round_trip_is_bit_for_bit(tmp_path):
    xyz, rgb, sigma, uv = _cloud()
    p = tmp_path / "points.ply"
    write_points_ply(p, xyz, rgb, sigma, uv, comments=[units_comment("mm"), "made by a test"])
    d = read_ply(p)
    assert d["xyz"].dtype == np.float32 and d["xyz"].shape == xyz.shape
    assert d["xyz"].tobytes() == xyz.tobytes()
    assert d["rgb"].dtype == np.uint8 and np.array_equal(d["rgb"], rgb)
    assert d["sigma"].tobytes() == sigma.tobytes()
    assert d["uv"].tobytes() == uv.tobytes()
    assert d["comments"] == ["units mm", "made by a test"]
    assert "faces" not in d


def test_points_header_layout(tmp_path):
    xyz, rgb, sigma, uv = _cloud(10)
    p = tmp_path / "points.ply"
    write_points_ply(p, xyz, rgb, sigma, uv)
    lines = _header(p)
    assert lines[:2] == ["ply", "format binary_little_endian 1.0"]
    props = [line for line in lines if line.startswith(("element", "property"))]
    assert props == [
        "element vertex 10",
        "property float x", "property float y", "property float z",
        "property uchar red", "property uchar green", "property uchar blue",
        "property float scalar_sigma", "property float quality",
        "property float scalar_u", "property float scalar_v",
    ]
    # packed records: 3*4 + 3 + 2*4 + 2*4 = 31 bytes per vertex
    body = p.read_bytes().split(b"end_header\n", 1)[1]
    assert len(body) == 10 * 31
    assert body[:4] == xyz[0, 0].astype("<f4").tobytes()


def test_points_without_optional_fields(tmp_path):
    xyz, *_ = _cloud(7)
    p = tmp_path / "bare.ply"
    write_points_ply(p, xyz)
    d = read_ply(p)
    assert d["xyz"].tobytes() == xyz.tobytes()
    assert not {"rgb", "sigma", "uv"} & d.keys()
    assert len(p.read_bytes().split(b"end_header\n", 1)[1]) == 7 * 12


def test_empty_cloud(tmp_path):
    p = tmp_path / "empty.ply"
    write_points_ply(p, np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8), np.zeros(0, np.float32))
    d = read_ply(p)
    assert d["xyz"].shape == (0, 3) and d["rgb"].shape == (0, 3) and d["sigma"].shape == (0,)


def test_mesh_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    v = rng.normal(size=(50, 3)).astype(np.float32)
    f = rng.integers(0, 50, size=(80, 3)).astype(np.int32)
    rgb = rng.integers(0, 256, size=(50, 3), dtype=np.uint8)
    p = tmp_path / "mesh.ply"
    write_mesh_ply(p, v, f, rgb, comments=[units_comment("m")])
    d = read_ply(p)
    assert d["xyz"].tobytes() == v.tobytes()
    assert np.array_equal(d["rgb"], rgb)
    assert d["faces"].dtype == np.int32 and np.array_equal(d["faces"], f)
    assert d["comments"] == ["units m"]
    assert "element face 80" in _header(p)
    assert "property list uchar int vertex_indices" in _header(p)
    body = p.read_bytes().split(b"end_header\n", 1)[1]
    assert len(body) == 50 * 15 + 80 * 13


def test_mesh_without_colour_and_faces(tmp_path):
    v = np.zeros((3, 3), np.float32)
    p = tmp_path / "m.ply"
    write_mesh_ply(p, v, np.zeros((0, 3), np.int32), None)
    d = read_ply(p)
    assert d["xyz"].shape == (3, 3) and d["faces"].shape[0] == 0 and "rgb" not in d


def test_mesh_rejects_bad_indices(tmp_path):
    with pytest.raises(ValueError):
        write_mesh_ply(tmp_path / "m.ply", np.zeros((3, 3), np.float32), np.array([[0, 1, 3]]))
    assert not list(tmp_path.iterdir())


def test_write_is_atomic(tmp_path, monkeypatch):
    xyz, rgb, sigma, uv = _cloud(20)
    p = tmp_path / "points.ply"
    write_points_ply(p, xyz, rgb)
    before = p.read_bytes()
    # Bad shapes fail before anything is written; the old file stays whole.
    with pytest.raises(ValueError):
        write_points_ply(p, xyz, rgb[:5])
    assert p.read_bytes() == before
    # A failure while writing (after part of the file is out) removes the temporary
    # file and leaves the old file.
    real_open = open

    class Failing:
        def __init__(self, path, mode):
            self.fh = real_open(path, mode)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

        def write(self, data):
            self.fh.write(data[:10])
            raise OSError("disk full")

    monkeypatch.setattr("gnomon.outputs.ply.open", Failing, raising=False)
    with pytest.raises(OSError, match="disk full"):
        write_points_ply(p, xyz, rgb, sigma, uv)
    monkeypatch.undo()
    assert p.read_bytes() == before
    assert sorted(x.name for x in tmp_path.iterdir()) == ["points.ply"]


def test_read_ascii_and_big_endian(tmp_path):
    a = tmp_path / "a.ply"
    a.write_text(
        "ply\nformat ascii 1.0\ncomment hello\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    )
    d = read_ply(a)
    assert np.array_equal(d["xyz"], np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32))
    assert np.array_equal(d["faces"], [[0, 1, 2]])
    assert d["comments"] == ["hello"]

    b = tmp_path / "b.ply"
    xyz = np.array([[1.5, -2.25, 3.0]], dtype=">f4")
    b.write_bytes(
        b"ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
        b"property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
        + xyz.tobytes() + bytes([1, 2, 3])
    )
    d = read_ply(b)
    assert np.array_equal(d["xyz"], [[1.5, -2.25, 3.0]]) and np.array_equal(d["rgb"], [[1, 2, 3]])


def test_read_variable_length_faces(tmp_path):
    p = tmp_path / "quad.ply"
    body = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], "<f4").tobytes()
    body += bytes([4]) + np.array([0, 1, 2, 3], "<i4").tobytes() + bytes([3]) + np.array([0, 1, 2], "<i4").tobytes()
    p.write_bytes(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        b"property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n" + body
    )
    faces = read_ply(p)["faces"]
    assert faces.dtype == object and [list(f) for f in faces] == [[0, 1, 2, 3], [0, 1, 2]]


@pytest.mark.parametrize(
    "content, message",
    [
        (b"hello world\n", "not a PLY file"),
        (b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nend_header\n\x00\x00",
         "truncated"),
        (b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty quux x\nend_header\n", "bad PLY header"),
        (b"ply\nformat foo 1.0\nend_header\n", "unsupported PLY format"),
    ],
)
def test_bad_files_raise_gnomon_error_naming_the_file(tmp_path, content, message):
    p = tmp_path / "bad.ply"
    p.write_bytes(content)
    with pytest.raises(GnomonError) as info:
        read_ply(p)
    text = str(info.value)
    assert str(p) in text and message in text and "\n" not in text


def test_missing_file(tmp_path):
    with pytest.raises(GnomonError, match="no such file"):
        read_ply(tmp_path / "nope.ply")
