"""Survey deliverables: LAS/LAZ clouds with their CRS, heights in a named datum, headings from a named north.

The coordinates are checked against PROJ's own topocentric pipeline (East-North-Up at the site →
geocentric → UTM), which Gnomon's writer does not use (it rotates the ENU offsets into geocentric
coordinates itself), read back with laspy, the CRS parsed by pyproj.
"""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

import laspy
import numpy as np
import pytest
from pyproj import CRS, Transformer

from gnomon.cli import main
from gnomon.config.fieldlog import load_field_log
from gnomon.errors import GnomonError
from gnomon.outputs.crs import local_crs, survey_frame
from gnomon.outputs.las import write_las
from gnomon.util import toml_io

ROOT = Path(__file__).resolve().parents[1]
SITE = {"latitude_deg": 47.3769, "longitude_deg": 8.5417, "altitude_m": 408.0}


def topocentric_to_utm(enu: np.ndarray, site: dict, zone: int) -> np.ndarray:
    """PROJ's pipeline from ENU metres at the site to UTM (WGS 84), heights above the ellipsoid."""
    t = Transformer.from_pipeline(
        f"+proj=pipeline +step +inv +proj=topocentric +lat_0={site['latitude_deg']} +lon_0={site['longitude_deg']} "
        f"+h_0={site['altitude_m']} +ellps=WGS84 +step +inv +proj=cart +ellps=WGS84 "
        f"+step +proj=utm +zone={zone} +ellps=WGS84")
    x, y, z = t.transform(enu[:, 0], enu[:, 1], enu[:, 2])
    return np.stack([x, y, z], axis=1)


def _enu_cloud(n: int = 500, extent: float = 150.0, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform([-extent, -extent, -5.0], [extent, extent, 40.0], size=(n, 3))


@pytest.mark.parametrize("datum", ["ellipsoidal", "orthometric"])
def test_a_georeferenced_cloud_is_in_utm_within_a_millimetre(tmp_path: Path, datum: str) -> None:
    site = {**SITE, "altitude_datum": datum}
    enu = _enu_cloud()
    frame = survey_frame(site)
    xyz = frame.from_enu(enu, site)
    rgb = np.tile(np.array([[10, 200, 30]], np.uint8), (len(enu), 1))
    sigma = np.linspace(0.001, 0.01, len(enu)).astype(np.float32)
    uv = np.stack([np.arange(len(enu)), np.arange(len(enu)) * 0.5], axis=1).astype(np.float32)
    path = tmp_path / "points.laz"
    write_las(path, xyz, frame.crs, resolution=1e-4, rgb=rgb, sigma=sigma, uv=uv)

    las = laspy.read(path)
    crs = las.header.parse_crs()
    assert crs is not None and crs.to_epsg() in (None, 32632) and "UTM zone 32N" in crs.name
    if datum == "orthometric":
        assert crs.is_compound and "EGM2008" in crs.name
    else:
        assert crs.is_projected and len(crs.axis_info) == 3  # heights above the ellipsoid
    read = np.stack([las.x, las.y, las.z], axis=1)
    reference = topocentric_to_utm(enu, site, 32)
    assert np.abs(read - reference).max() < 1e-3  # metres: within 1 mm over 300 m of ground
    assert np.abs(read[:, :2]).min() > 1e5  # projected metres (an easting, a northing), not ENU offsets
    assert np.allclose(las.sigma, sigma) and np.allclose(las.pixel_u, uv[:, 0]) and np.allclose(las.pixel_v, uv[:, 1])
    assert (las.red == 10 * 257).all() and (las.green == 200 * 257).all()


def test_any_crs_on_request(tmp_path: Path) -> None:
    """EPSG:2056 (Swiss LV95, heights of its own datum given): the same points as PROJ puts them."""
    site = {**SITE, "altitude_datum": "ellipsoidal"}
    enu = _enu_cloud(50)
    frame = survey_frame(site, "EPSG:2056")
    xyz = frame.from_enu(enu, site)
    utm = topocentric_to_utm(enu, site, 32)
    to_lv95 = Transformer.from_crs(CRS.from_epsg(32632).to_3d(), CRS.from_epsg(2056).to_3d(), always_xy=True)
    ex, ey, _ = to_lv95.transform(utm[:, 0], utm[:, 1], utm[:, 2])
    assert np.abs(xyz[:, 0] - ex).max() < 1e-3 and np.abs(xyz[:, 1] - ey).max() < 1e-3
    write_las(tmp_path / "p.las", xyz, frame.crs, resolution=1e-4)
    assert "LV95" in laspy.read(tmp_path / "p.las").header.parse_crs().name


def test_a_desk_cloud_declares_its_units(tmp_path: Path) -> None:
    xyz = np.array([[0.0, 0.0, 0.0], [120.5, -30.25, 78.125]])
    write_las(tmp_path / "d.las", xyz, local_crs("mm"), resolution=0.01)
    las = laspy.read(tmp_path / "d.las")
    crs = las.header.parse_crs()
    assert crs.axis_info[0].unit_name == "millimetre"
    assert np.allclose(np.stack([las.x, las.y, las.z], axis=1), xyz, atol=0.005)


def _facade_log(tmp_path: Path, **site: object) -> Path:
    src = ROOT / "field_logs" / "facade_sun_small"
    dst = tmp_path / "facade"
    shutil.copytree(src, dst)
    data = tomllib.loads((dst / "field_log.toml").read_text())
    data["site"].update(site)
    toml_io.dump(data, dst / "field_log.toml")
    return dst / "field_log.toml"


def test_site_datum_and_north_are_explicit(tmp_path: Path) -> None:
    log = load_field_log(_facade_log(tmp_path, heading_north="magnetic", declination_deg=2.5, heading_deg=300.0,
                                     altitude_datum="ellipsoidal"))
    assert log.site is not None and log.site.heading_deg == pytest.approx(302.5)  # from true north
    assert log.site.altitude_datum == "ellipsoidal"
    with pytest.raises(GnomonError, match="declination_deg"):
        load_field_log(_facade_log(tmp_path / "b", heading_north="magnetic"))
    with pytest.raises(GnomonError, match="altitude_datum"):
        load_field_log(_facade_log(tmp_path / "c", altitude_datum="sea"))


@pytest.mark.slow
def test_a_sun_scan_writes_laz_in_utm_matching_its_enu_cloud(tmp_path: Path) -> None:
    log = _facade_log(tmp_path)
    out = tmp_path / "scan"
    assert main(["scan", str(log), "--out", str(out), "--quiet", "--no-rrd"]) == 0
    from gnomon.outputs.ply import read_ply

    enu = read_ply(out / "points_enu.ply")["xyz"].astype(np.float64)
    las = laspy.read(out / "points.laz")
    site = {k: float(v) for k, v in tomllib.loads(log.read_text())["site"].items() if k in ("latitude", "longitude")}
    site = {"latitude_deg": site["latitude"], "longitude_deg": site["longitude"],
            "altitude_m": float(tomllib.loads(log.read_text())["site"].get("altitude", 0.0))}
    zone = int(las.header.parse_crs().sub_crs_list[0].to_epsg()) - 32600
    reference = topocentric_to_utm(enu, site, zone)
    read = np.stack([las.x, las.y, las.z], axis=1)
    # points_enu.ply holds float32 metres near the site (0.1 mm at 30 m): within 1 mm all the same
    assert len(read) == len(enu) > 1000
    assert np.abs(read - reference).max() < 1e-3
    assert np.isfinite(las.sigma).all() and (las.sigma > 0).all()
    # a desk-frame request is refused in one line: a CRS needs a georeferenced scan
    assert main(["scan", str(ROOT / "field_logs" / "desk_lamp_small" / "field_log.toml"), "--out",
                 str(tmp_path / "desk"), "--quiet", "--no-rrd", "--crs", "EPSG:2056"]) == 2
    assert not (tmp_path / "desk").exists()


def test_sigma_is_a_field_the_mesh_tools_keep(tmp_path: Path) -> None:
    """points.ply's σ: MeshLab (pymeshlab) reads it as the vertex quality; our reader reads this version's
    names and an earlier version's (sigma, u, v)."""
    pymeshlab = pytest.importorskip("pymeshlab")
    from gnomon.outputs.ply import read_ply, write_points_ply

    xyz = np.arange(30, dtype=np.float32).reshape(10, 3)
    sigma = np.linspace(0.1, 1.0, 10).astype(np.float32)
    uv = np.stack([np.arange(10), np.arange(10) + 0.5], axis=1).astype(np.float32)
    write_points_ply(tmp_path / "p.ply", xyz, sigma=sigma, uv=uv, comments=["units mm"])
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(tmp_path / "p.ply"))
    mesh = ms.current_mesh()
    assert mesh.has_vertex_scalar()
    np.testing.assert_allclose(mesh.vertex_scalar_array(), sigma, rtol=1e-6)
    header = (tmp_path / "p.ply").read_bytes().split(b"end_header")[0].decode()
    assert "property float scalar_sigma" in header and "obj_info units mm" in header  # CloudCompare's names
    d = read_ply(tmp_path / "p.ply")
    assert np.array_equal(d["sigma"], sigma) and np.array_equal(d["uv"], uv)
    old = (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
           b"property float sigma\nproperty float u\nproperty float v\nend_header\n1 2 3 0.5 7 8\n")
    (tmp_path / "old.ply").write_bytes(old)
    d = read_ply(tmp_path / "old.ply")
    assert d["sigma"].tolist() == [0.5] and d["uv"].tolist() == [[7.0, 8.0]]
