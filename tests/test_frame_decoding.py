"""Image files are decoded on several threads at once, delivered in order, with the frames in flight bounded,
and a failing file stops the pass cleanly (its error names it, no thread is left behind, nothing hangs)."""

from __future__ import annotations

import hashlib
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from gnomon.capture.frames import FRAMES_IN_FLIGHT, FrameSource, decode_workers
from gnomon.errors import FrameError


def write_frames(folder: Path, n: int, size: tuple[int, int] = (96, 64)) -> list[Path]:
    """n PNG frames, each a different ramp (frame i's top-left sample is i), so order is visible."""
    folder.mkdir(parents=True, exist_ok=True)
    w, h = size
    paths = []
    for i in range(n):
        image = ((np.arange(w)[None, :] + 3 * np.arange(h)[:, None] + i) % 256).astype(np.uint8)
        image[0, 0] = i
        path = folder / f"frame_{i:03d}.png"
        cv2.imwrite(str(path), image)
        paths.append(path)
    return paths


def decoding_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("gnomon-frame-decode")]


def test_frames_arrive_in_order_equal_to_a_sequential_decode(tmp_path: Path) -> None:
    paths = write_frames(tmp_path / "frames", 40)
    source = FrameSource(tuple(paths))
    frames = list(source)
    assert [f.index for f in frames] == list(range(40))
    assert [f.name for f in frames] == [p.name for p in paths]
    for f, p in zip(frames, paths, strict=True):
        assert np.array_equal(f.grey, cv2.imread(str(p), cv2.IMREAD_UNCHANGED))
    h = hashlib.sha256()
    for p in paths:
        h.update(p.read_bytes())
    assert source.frames_digest() == h.hexdigest()
    assert not decoding_threads()


def test_the_frames_in_flight_are_bounded(tmp_path: Path) -> None:
    """A consumer that holds a frame lets the decoders run ahead by at most FRAMES_IN_FLIGHT frames: the
    others are not read."""
    paths = write_frames(tmp_path / "frames", 60)
    reads: list[str] = []

    class CountingPath(type(tmp_path)):  # type: ignore[misc]  # the concrete Path class of this platform
        def read_bytes(self) -> bytes:
            reads.append(self.name)
            return super().read_bytes()

    frames = iter(FrameSource(tuple(CountingPath(p) for p in paths)))
    first = next(frames)
    assert first.index == 0
    time.sleep(0.3)  # the decoders would go on if nothing bounded them
    assert decode_workers() <= len(reads) <= 1 + FRAMES_IN_FLIGHT
    second = next(frames)
    assert second.index == 1
    time.sleep(0.3)
    assert len(reads) <= 2 + FRAMES_IN_FLIGHT
    frames.close()  # leaving early: the frames not started are cancelled, the running ones awaited
    assert not decoding_threads()
    assert len(reads) <= 2 + FRAMES_IN_FLIGHT


@pytest.mark.parametrize("fault", ["truncated", "not an image", "other size", "missing"])
def test_a_bad_file_is_an_error_naming_it_after_the_frames_before_it(tmp_path: Path, fault: str) -> None:
    paths = write_frames(tmp_path / "frames", 30)
    bad = paths[17]
    if fault == "truncated":
        bad.write_bytes(bad.read_bytes()[:200])
    elif fault == "not an image":
        bad.write_bytes(b"not an image at all" * 10)
    elif fault == "other size":
        cv2.imwrite(str(bad), np.zeros((10, 10), np.uint8))
    else:
        bad.unlink()
    taken: list[int] = []
    outcome: list[BaseException] = []

    def consume() -> None:
        try:
            for frame in FrameSource(tuple(paths)):
                taken.append(frame.index)
        except BaseException as exc:  # noqa: BLE001 - the test inspects it
            outcome.append(exc)

    consumer = threading.Thread(target=consume)
    consumer.start()
    consumer.join(timeout=30)
    assert not consumer.is_alive(), "the pass hung after a decoding thread failed"
    assert taken == list(range(17))
    assert len(outcome) == 1 and isinstance(outcome[0], FrameError)
    assert "frame_017.png" in str(outcome[0])
    assert not decoding_threads()


def test_a_peek_leaves_no_thread_and_the_next_pass_is_whole(tmp_path: Path) -> None:
    paths = write_frames(tmp_path / "frames", 25)
    source = FrameSource(tuple(paths))
    for frame in source:
        assert frame.index == 0
        break
    assert not decoding_threads()
    assert [f.index for f in source] == list(range(25))


def test_the_colour_frames_asked_for_come_with_their_colour(tmp_path: Path) -> None:
    folder = tmp_path / "frames"
    folder.mkdir()
    paths = []
    for i in range(12):
        bgr = np.zeros((20, 30, 3), np.uint8)
        bgr[..., 0], bgr[..., 1], bgr[..., 2] = 10 * i, 100, 200 - 10 * i
        paths.append(folder / f"f_{i:02d}.png")
        cv2.imwrite(str(paths[-1]), bgr)
    source = FrameSource(tuple(paths))
    source.color_frames = frozenset({0, 5, 9})
    frames = list(source)
    assert [i for i, f in enumerate(frames) if f.color is not None] == [0, 5, 9]
    assert np.array_equal(frames[5].color, cv2.imread(str(paths[5]), cv2.IMREAD_COLOR))
    assert np.array_equal(frames[7].grey, cv2.cvtColor(cv2.imread(str(paths[7])), cv2.COLOR_BGR2GRAY))


def test_a_jpeg_captures_grey_is_its_luma_in_every_frame(tmp_path: Path) -> None:
    """Colour JPEG frames: every frame's grey is the luma channel as coded (OpenCV's grey decode of the
    file), the frames kept in colour included, within JPEG's error of the BT.601 luma of the image
    that was encoded; a kept frame's colour is OpenCV's colour decode."""
    folder = tmp_path / "frames"
    folder.mkdir()
    yy, xx = np.mgrid[0:48, 0:64]
    paths, lumas = [], []
    for i in range(6):
        # smooth colour patterns, some channels clipped (where luma and the colour round trip differ)
        bgr = np.stack([127.5 + 160 * np.sin(xx / 9.0 + k + i) * np.cos(yy / 7.0 - k) for k in (0, 2, 4)], -1)
        bgr = np.clip(bgr, 0, 255).round().astype(np.uint8)
        lumas.append(bgr @ np.array([0.114, 0.587, 0.299]))
        paths.append(folder / f"f_{i:02d}.jpg")
        cv2.imwrite(str(paths[-1]), bgr, [cv2.IMWRITE_JPEG_QUALITY, 95])
    source = FrameSource(tuple(paths))
    source.color_frames = frozenset({0, 3})
    frames = list(source)
    round_trip_differs = 0
    for f, p, luma in zip(frames, paths, lumas, strict=True):
        assert np.array_equal(f.grey, cv2.imread(str(p), cv2.IMREAD_GRAYSCALE))
        # q95 JPEG of 8-bit samples: well under 1 DN RMS, a few DN at most
        assert np.sqrt(np.mean((f.grey - luma) ** 2)) < 1.0
        colour = cv2.imread(str(p), cv2.IMREAD_COLOR)
        round_trip_differs += int(np.count_nonzero(f.grey != cv2.cvtColor(colour, cv2.COLOR_BGR2GRAY)))
    assert [i for i, f in enumerate(frames) if f.color is not None] == [0, 3]
    assert np.array_equal(frames[3].color, cv2.imread(str(paths[3]), cv2.IMREAD_COLOR))
    assert round_trip_differs > 0  # the frames do tell the luma from the colour round trip


# --------------------------------------------------------------------------- per-file checks' fast paths


def _encoded_images() -> list[bytes]:
    """JPEGs as OpenCV writes them (no APP1), as Pillow writes them with EXIF (each orientation) and
    with XMP only, a PNG, and bytes that are no image."""
    import io

    from PIL import Image

    rng = np.random.default_rng(3)
    grey = rng.integers(0, 256, (37, 53), dtype=np.uint8)
    colour = rng.integers(0, 256, (29, 41, 3), dtype=np.uint8)
    out = [cv2.imencode(".jpg", grey)[1].tobytes(), cv2.imencode(".jpg", colour)[1].tobytes(),
           cv2.imencode(".png", grey)[1].tobytes(), b"", b"\xff\xd8", b"\xff\xd8\xff\xd9", b"GIF89a not really"]
    for orientation in range(1, 9):
        exif = Image.Exif()
        exif[0x0112] = orientation
        buf = io.BytesIO()
        Image.fromarray(colour).save(buf, "JPEG", exif=exif, quality=90)
        out.append(buf.getvalue())
    xmp = (b'<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">'
           b'<rdf:Description xmlns:tiff="http://ns.adobe.com/tiff/1.0/" tiff:Orientation="6"/></rdf:RDF></x:xmpmeta>')
    buf = io.BytesIO()
    Image.fromarray(grey).save(buf, "JPEG", xmp=xmp)
    out.append(buf.getvalue())
    return out


def _variants(raw: bytes) -> list[bytes]:
    """The file, cut at many places (within the headers too), and with bytes after its end."""
    cuts = sorted({*range(0, min(len(raw), 700), 7), *np.linspace(0, len(raw), 40).astype(int).tolist(),
                   *range(max(len(raw) - 6, 0), len(raw) + 1)})
    return [raw[:c] for c in cuts] + [raw + b"\x00", raw + b"\xff", raw + b"\xff\xda\x00\x08", raw + b"\xff\xd9"]


def test_truncation_verdicts_are_the_definitions() -> None:
    from gnomon.capture.frames import _truncation_problem_scan, truncation_problem

    checked = 0
    for raw in _encoded_images():
        for variant in _variants(raw):
            assert truncation_problem(variant) == _truncation_problem_scan(variant), (raw[:4], len(variant))
            checked += 1
    assert checked > 500
    # SOS as the very last bytes before EOI, and EOI overlapping the SOS marker's bytes
    edge_cases = (b"\xff\xd8\xff\xda\xff\xd9", b"\xff\xd8\xff\xda\xd9", b"\xff\xd8\x00\xff\xda",
                  b"\xff\xd8\xff\xd9\xff\xd9")
    for raw in edge_cases:
        assert truncation_problem(raw) == _truncation_problem_scan(raw)


def test_exif_orientation_is_pillows_and_skips_it_without_app1() -> None:
    from gnomon.capture.frames import _exif_orientation_pillow, _jpeg_has_app1, exif_orientation

    images = _encoded_images()
    assert not _jpeg_has_app1(images[0]) and not _jpeg_has_app1(images[1])  # OpenCV's: the fast path
    assert [exif_orientation(raw) for raw in images[7:15]] == list(range(1, 9))  # Pillow's EXIF
    assert exif_orientation(images[15]) == _exif_orientation_pillow(images[15])  # XMP only
    for raw in images:
        for variant in _variants(raw)[::3]:
            assert exif_orientation(variant) == _exif_orientation_pillow(variant), (raw[:4], len(variant))
    # fill bytes and standalone markers before the segments, and a malformed length
    jpeg = images[0]
    for raw in (jpeg[:2] + b"\xff\xff" + jpeg[2:], jpeg[:2] + b"\xff\xd0" + jpeg[2:], jpeg[:2] + b"\xff\xe0\x00\x01"):
        assert exif_orientation(raw) == _exif_orientation_pillow(raw)
