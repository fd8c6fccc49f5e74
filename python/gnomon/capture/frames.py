"""Frame readers: image folders and video files, decoded on background threads.

Frames are delivered one at a time, in order, as grey images (uint8 or uint16,
as encoded), so a scan never holds the whole sequence in memory. Decoding runs
ahead of the consumer (OpenCV releases the GIL while decoding), at most
``FRAMES_IN_FLIGHT`` frames ahead: image files on several threads at once
(``decode_workers()``: one per core, at most 4; each file is independent), a
video on one reader thread (its frames depend on each other) through a bounded
queue.

Problems with the input raise :class:`FrameError` naming the frame: a file that
cannot be decoded or is truncated (the decoder only warns about those), a frame whose size
differs from the first, a video that ends before the number of frames it announced (or the field log expects).
A JPEG whose data is corrupt inside (bytes lost or zeroed mid-file: libjpeg warns and decodes the rest as
garbage) raises :class:`~gnomon.errors.CorruptFrameError`: JPEGs are decoded by libjpeg-turbo through
simplejpeg, which stops on the decoder's warnings (:func:`decode_jpeg`); a source built with
``on_corrupt="drop"`` leaves such a frame out instead and lists it (:attr:`FrameSource.dropped`).

Image files are turned upright by their EXIF orientation tag (as a phone
records a portrait photo) wherever Gnomon reads them: :func:`decode_image_file`,
:func:`image_size` and :func:`gnomon.camera.calibration.read_grey` all go through
:func:`apply_exif_orientation`. :func:`glob_frames` matches a pattern's file
suffix in any case (``*.jpg`` finds ``.JPG`` too).
"""

from __future__ import annotations

import glob
import hashlib
import io
import os
import re
from collections import deque
from collections.abc import Iterable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import simplejpeg

from gnomon.errors import CorruptFrameError, FrameError
from gnomon.util.threads import ahead

FRAMES_IN_FLIGHT = 8
"""Frames decoded ahead of the consumer, at most (image files: submitted to the decoding threads and
not yet taken; a video: in the reader's queue)."""

#: The file suffixes read as a video (any case); any other file is an image.
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm")


def decode_workers() -> int:
    """Threads decoding image files at once: the cores this process may run on, at most 4."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, 4))


def sha256_file(path: Path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def to_grey(image: np.ndarray) -> np.ndarray:
    """A decoded frame (grey, BGR or BGRA; 8 or 16 bit) as a 2-D grey image of the same depth."""
    if image.ndim == 2:
        return image
    if image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY)
    if image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    return image[:, :, 0]


def grey_8bit_scale(image: np.ndarray) -> np.ndarray:
    """An image (grey, BGR or BGRA) as float32 grey on an 8-bit scale: uint8 as is, uint16 / 257,
    other types taken as 0..1 (× 255). For detectors that want 8-bit levels (markers, ArUco)."""
    img = to_grey(np.asarray(image))
    if img.dtype == np.uint8:
        return img.astype(np.float32)
    if img.dtype == np.uint16:
        return (img.astype(np.float32) / 257.0).astype(np.float32)
    return (img.astype(np.float32) * 255.0).astype(np.float32)


_JPEG_SOI, _JPEG_SOS, _JPEG_EOI = b"\xff\xd8", b"\xff\xda", b"\xff\xd9"
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_IEND = b"IEND\xaeB`\x82"
_PNG_EXIF = b"eXIf"  # the type of a PNG's EXIF chunk


def truncation_problem(raw: bytes) -> str | None:
    """Why an encoded JPEG or PNG file is incomplete, or None.

    A JPEG cut short (a copy interrupted, a card pulled) still decodes: libjpeg
    warns "premature end of data segment" and fills the rest of the image with
    grey, and OpenCV prints the warning but returns the image. So the bytes are
    checked instead (cheap, no second decode): a JPEG's last scan (after its
    last SOS marker; entropy-coded data cannot contain a bare 0xFFD9) must be
    followed by the EOI marker, and a PNG must hold its IEND chunk. Other
    formats are not checked.

    A JPEG that ends with EOI (nearly every one) only needs an SOS anywhere: the last SOS cannot
    overlap the final EOI, so EOI follows it. That SOS is looked for from the start, where it follows
    the headers, instead of from the end through the whole image data and back (≈ 0.45 ms per 1080p
    frame). The same verdicts as :func:`_truncation_problem_scan`, the definition.
    """
    if raw.startswith(_JPEG_SOI) and raw.endswith(_JPEG_EOI):
        return None if _JPEG_SOS in raw else "a JPEG without image data (no SOS marker)"
    return _truncation_problem_scan(raw)


def _truncation_problem_scan(raw: bytes) -> str | None:
    """:func:`truncation_problem` by its definition: the last SOS found from the end, then an EOI after it."""
    if raw.startswith(_JPEG_SOI):
        sos = raw.rfind(_JPEG_SOS)
        if sos < 0:
            return "a JPEG without image data (no SOS marker)"
        if raw.find(_JPEG_EOI, sos + 2) < 0:
            return "a truncated JPEG (its data ends before the end-of-image marker)"
    elif raw.startswith(_PNG_SIGNATURE) and raw.rfind(_PNG_IEND) < 0:
        return "a truncated PNG (no IEND chunk)"
    return None


_EXIF_ORIENTATION = 0x0112


def exif_orientation(raw: bytes) -> int:
    """The EXIF orientation tag (1–8) of an encoded image; 1 (upright) when absent or unreadable.

    Read by Pillow, which finds it in a JPEG's APP1 segments (EXIF, or XMP without EXIF); a JPEG whose
    header has no APP1 segment (:func:`_jpeg_has_app1`: OpenCV's and most encoders' frames), and a PNG
    without an ``eXIf`` chunk anywhere, are upright without opening them in Pillow (≈ 0.4 ms per JPEG frame;
    a PNG is decoded whole by Pillow's EXIF look-up, ≈ 20 ms at 1080p).
    """
    if raw.startswith(_JPEG_SOI) and not _jpeg_has_app1(raw):
        return 1
    if raw.startswith(_PNG_SIGNATURE) and _PNG_EXIF not in raw:
        return 1  # Pillow would decode the whole PNG to look for its EXIF chunk (≈ 20 ms at 1080p)
    return _exif_orientation_pillow(raw)


def _exif_orientation_pillow(raw: bytes) -> int:
    """:func:`exif_orientation` by Pillow, for any image (the definition)."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(raw)) as im:
            value = im.getexif().get(_EXIF_ORIENTATION, 1)
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError):
        return 1
    return int(value) if isinstance(value, int) and 1 <= value <= 8 else 1


_JPEG_APP1, _JPEG_SOS_BYTE, _JPEG_EOI_BYTE = 0xE1, 0xDA, 0xD9
_JPEG_STANDALONE = frozenset({0x01, *range(0xD0, 0xD8)})  # TEM and RST0–7: no length field


def _jpeg_has_app1(raw: bytes) -> bool:
    """Whether the header segments of a JPEG (``raw`` starts with SOI) before its first SOS include an
    APP1 (EXIF, XMP). True also when the segments cannot be walked (a byte that is not a marker where
    one must be, a length below 2, data ending first), so that Pillow decides those."""
    pos, end = len(_JPEG_SOI), len(raw)
    while pos + 4 <= end:
        if raw[pos] != 0xFF:
            return True
        marker = raw[pos + 1]
        if marker == 0xFF:  # a fill byte before a marker
            pos += 1
        elif marker == _JPEG_APP1:
            return True
        elif marker in (_JPEG_SOS_BYTE, _JPEG_EOI_BYTE):
            return False
        elif marker in _JPEG_STANDALONE:
            pos += 2
        else:
            length = int.from_bytes(raw[pos + 2:pos + 4], "big")
            if length < 2:
                return True
            pos += 2 + length
    return True


def apply_exif_orientation(image: np.ndarray, orientation: int) -> np.ndarray:
    """Turn a decoded image (H, W[, C]) upright according to its EXIF orientation (1–8).

    1 upright; 2 mirrored left–right; 3 turned 180°; 4 mirrored top–bottom;
    5 transposed; 6 stored turned 90° anticlockwise (shown turned 90°
    clockwise); 7 transversed; 8 stored turned 90° clockwise.
    """
    if orientation == 2:
        out = image[:, ::-1]
    elif orientation == 3:
        out = image[::-1, ::-1]
    elif orientation == 4:
        out = image[::-1]
    elif orientation == 5:
        out = image.swapaxes(0, 1)
    elif orientation == 6:
        out = np.rot90(image, k=-1)
    elif orientation == 7:
        out = image.swapaxes(0, 1)[::-1, ::-1]
    elif orientation == 8:
        out = np.rot90(image, k=1)
    else:
        return image
    return np.ascontiguousarray(out)


def decode_image_file(path: Path) -> tuple[np.ndarray, bytes]:
    """Decode an image file as stored (keeping 16-bit data), turned upright by its EXIF orientation.

    Returns the image and the file's raw bytes.

    Raises :class:`FrameError` naming the file when it cannot be read or
    decoded, or when it is truncated (see :func:`truncation_problem`: the
    decoder would only warn and hand back a partly grey image), and
    :class:`~gnomon.errors.CorruptFrameError` when a JPEG's data is corrupt inside (:func:`decode_jpeg`).
    """
    raw = _read_image_bytes(path)
    if raw.startswith(_JPEG_SOI):
        decoded = decode_jpeg(path, raw, colour=True)
        if decoded is not None:
            return decoded, raw
    return _decode(path, raw, cv2.IMREAD_UNCHANGED), raw


def decode_frame_file(path: Path, keep_colour: bool = False) -> tuple[np.ndarray, np.ndarray | None, bytes]:
    """A frame file as a scan reads it: its grey image (H, W; uint8 or uint16), with ``keep_colour``
    its BGR image ((H, W, 3); None for a grey file, or without ``keep_colour``), and the file's bytes.

    A JPEG's grey is its luma channel as coded, decoded alone: the decoder then skips the chroma's
    transforms, upsampling and colour conversion (half the time of a colour 1024×768 frame). It is
    the BT.601 weighting :func:`to_grey` applies to the decoded colour image, without that round
    trip's rounding and clipping (the two differ on under 1 % of pixels, where a colour is clipped).
    Every frame of a JPEG capture has that grey, those also kept in colour included. Other formats:
    :func:`to_grey` of the image as stored. Errors as :func:`decode_image_file`.
    """
    raw = _read_image_bytes(path)
    if raw.startswith(_JPEG_SOI):
        grey = decode_jpeg(path, raw, colour=False)
        if grey is not None:
            colour = decode_jpeg(path, raw, colour=True) if keep_colour else None
            return grey, (colour if colour is not None and colour.ndim == 3 else None), raw
        # a JPEG simplejpeg does not decode (CMYK, 12-bit, an unusual sampling): OpenCV's decoder
        image = _decode(path, raw, cv2.IMREAD_UNCHANGED) if keep_colour else None
        grey = _decode(path, raw, cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH | cv2.IMREAD_IGNORE_ORIENTATION)
        return grey, (image[:, :, :3] if image is not None and image.ndim == 3 else None), raw
    image = _decode(path, raw, cv2.IMREAD_UNCHANGED)
    return to_grey(image), (image[:, :, :3] if keep_colour and image.ndim == 3 else None), raw


def decode_jpeg(path: Path, raw: bytes, colour: bool) -> np.ndarray | None:
    """A JPEG's bytes (``raw``, of ``path``) decoded strictly by libjpeg-turbo (simplejpeg), upright by its
    EXIF orientation: with ``colour`` as BGR (H, W, 3) (a grey JPEG: (H, W)), else its luma (H, W), uint8.

    libjpeg only warns about data corrupt inside the file (bytes zeroed or lost mid-file: "Corrupt JPEG
    data: premature end of data segment", "bad Huffman code", "found marker … instead of RST") and
    decodes the rest as garbage; OpenCV's decoder prints the warning and returns that image. Here a
    warning stops the decoding: :class:`~gnomon.errors.CorruptFrameError` naming the file and the
    decoder's words. The pixels are libjpeg-turbo's own, as OpenCV's (the same library, the same
    integer DCT): equal value for value (``tests/test_frame_decoding.py``).

    None for a JPEG simplejpeg does not decode at all (CMYK, 12-bit samples, a sampling TurboJPEG does not
    know): the caller decodes it with OpenCV, unchecked.
    """
    try:
        image = simplejpeg.decode_jpeg(raw, "BGR" if colour else "GRAY", strict=True)
    except ValueError as exc:
        try:  # a warning (the data decodes without strict) or an error (it does not)?
            simplejpeg.decode_jpeg(raw, "GRAY", strict=False)
        except ValueError:
            return None
        raise CorruptFrameError(path, str(exc).strip() or "the decoder warned") from None
    if colour and simplejpeg.decode_jpeg_header(raw)[2] == "Gray":
        image = image[:, :, 0]
    elif not colour:
        image = image[:, :, 0]
    return apply_exif_orientation(np.ascontiguousarray(image), exif_orientation(raw))


def _read_image_bytes(path: Path) -> bytes:
    """The bytes of an image file, refused (FrameError) when unreadable, empty or truncated."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise FrameError(f"{path}: cannot be read ({exc.strerror})") from None
    if not raw:
        raise FrameError(f"{path}: empty file (0 bytes)")
    problem = truncation_problem(raw)
    if problem is not None:
        raise FrameError(f"{path}: corrupt frame: {problem}")
    return raw


# ISO base media brands of HEIF images (HEIC: an iPhone's photos by default) and AVIF: OpenCV reads neither.
_HEIF_BRANDS = {b"heic", b"heix", b"heim", b"heis", b"hevc", b"hevx", b"hevm", b"hevs", b"mif1", b"msf1",
                b"avif", b"avis"}


def unsupported_format(raw: bytes) -> str | None:
    """What to tell the user about an image format OpenCV cannot decode, recognised by its first bytes
    (not its name), or None."""
    if len(raw) >= 12 and raw[4:8] == b"ftyp" and raw[8:12] in _HEIF_BRANDS:
        kind = "AVIF" if raw[8:12] in (b"avif", b"avis") else "HEIF/HEIC (an iPhone's default photo format)"
        return (f"{kind} is not read: export the images as JPEG or PNG (on an iPhone: Settings > Camera > "
                "Formats > Most Compatible takes JPEG photos)")
    return None


def _decode(path: Path, raw: bytes, flags: int) -> np.ndarray:
    """``raw`` (the bytes of ``path``) decoded with OpenCV's ``flags``, turned upright by its EXIF orientation."""
    try:
        image = cv2.imdecode(np.frombuffer(raw, np.uint8), flags)  # flags ignore EXIF: applied below
    except cv2.error as exc:  # e.g. a header claiming more pixels than OpenCV decodes
        reason = "its header claims more pixels than a frame can have" if "MAX_IMAGE_PIXELS" in str(exc) \
            else str(exc).strip().splitlines()[-1]
        raise FrameError(f"{path}: cannot be decoded: {reason}") from None
    if image is None or image.size == 0:
        raise FrameError(f"{path}: {unsupported_format(raw) or 'cannot be decoded as an image'}")
    if image.dtype not in (np.uint8, np.uint16):
        raise FrameError(f"{path}: unsupported sample type {image.dtype} (8- or 16-bit images only)")
    return apply_exif_orientation(image, exif_orientation(raw))


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) of an image file as shown (after its EXIF orientation), from its header."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            w, h = im.size
            orientation = im.getexif().get(_EXIF_ORIENTATION, 1)
    except Image.DecompressionBombError:
        raise FrameError(f"{path}: its header claims more pixels than a frame can have") from None
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError):
        image, _ = decode_image_file(path)  # formats PIL cannot read: decode (raises naming the file)
        return int(image.shape[1]), int(image.shape[0])
    return (h, w) if orientation in (5, 6, 7, 8) else (w, h)


# Video containers whose frame count OpenCV reads from an index of every frame (ISO base media: MP4,
# QuickTime). In the others it is the duration times the nominal frame rate, an estimate: a variable
# frame rate (a browser's WebM, a webcam app's Matroska) puts it off by many frames (a 60-frame WebM
# announced 72) and a constant one by one (59 for 60). Their frames are counted (decoded once, not
# converted) when the source is opened: a scan needs its frame count before the first frame.
EXACT_COUNT_SUFFIXES = (".mp4", ".mov", ".m4v")


def _count_frames(cap: cv2.VideoCapture) -> int:
    """Frames a freshly opened capture delivers to its end (``grab``: decoded, not converted)."""
    n = 0
    while cap.grab():
        n += 1
    return n


def _undecodable(video: Path, cap: cv2.VideoCapture) -> str:
    """Why a video opened but gave no frame: most often a codec OpenCV's FFmpeg does not decode (AV1)."""
    code = int(cap.get(cv2.CAP_PROP_FOURCC))
    fourcc = "".join(chr((code >> (8 * k)) & 0xFF) for k in range(4)).strip("\x00 ")
    codec = f"its codec '{fourcc}'" if fourcc.isprintable() and fourcc else "its codec"
    return (f"{video}: no frame could be decoded: {codec} is not one OpenCV's video decoder reads here "
            "(AV1 is not); convert it to H.264 (MP4) or to image frames")


def video_size(path: Path) -> tuple[int, int]:
    """(width, height) of a video's frames."""
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise FrameError(f"{path}: cannot be opened as a video")
        return int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
    finally:
        cap.release()


def video_fps(path: Path) -> float | None:
    """A video's announced frame rate (frames per second), or None when it announces none (0, NaN)."""
    cap = cv2.VideoCapture(str(path))
    try:
        fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
    finally:
        cap.release()
    return fps if np.isfinite(fps) and fps > 0 else None


def _any_case(suffix: str) -> str:
    return "".join(f"[{c.lower()}{c.upper()}]" if c.isalpha() else c for c in suffix)


def glob_frames(base: Path, pattern: str) -> tuple[Path, ...]:
    """Files matching ``pattern`` under ``base`` in natural order (``frame_2`` before ``frame_10``);
    the suffix matches in any case.

    ``frames/*.jpg`` finds ``IMG_0001.JPG`` too (cameras and phones write
    upper-case suffixes; Linux file systems are case-sensitive). Only a plain
    alphanumeric suffix of the pattern's last component is widened.
    """
    head, sep, name = pattern.rpartition("/")
    m = re.fullmatch(r"(.*\.)([A-Za-z0-9]+)", name)
    if m:
        pattern = head + sep + m.group(1) + _any_case(m.group(2))
    return tuple(sorted({p for p in base.glob(pattern) if p.is_file()}, key=natural_key))


def expand_glob_argument(argument: str | os.PathLike, what: str = "file") -> tuple[Path, ...] | None:
    """A command-line argument that names no existing path but is a glob pattern (``"frames/*.jpg"``,
    quoted, or from a shell that does not expand it) → the files it matches, as a field log's ``frames``
    matches them (:func:`glob_frames`: any-case suffix, natural order); None for any other argument.
    :class:`FrameError` naming the pattern when it matches no file (``what``: what the files are)."""
    text = os.fspath(argument)
    if os.path.lexists(text) or not glob.has_magic(text):
        return None
    parts = Path(text).parts
    first = next(i for i, part in enumerate(parts) if glob.has_magic(part))
    base = Path(*parts[:first]) if first else Path(".")
    found = glob_frames(base, "/".join(parts[first:]))
    if not found:
        raise FrameError(f"{text}: no {what} matches this pattern")
    return found


def natural_key(path: Path) -> tuple:
    """Sort key in which digit runs compare as numbers: frame_2 before frame_10 (as a camera numbers them)."""
    parts = re.split(r"(\d+)", str(path))
    return tuple((0, int(x), x) if x.isdigit() else (1, 0, x) for x in parts)


@dataclass
class Frame:
    index: int
    grey: np.ndarray  # (H, W) uint8 | uint16
    color: np.ndarray | None  # (H, W, 3) BGR, for the first frame and those FrameSource.color_frames names
    name: str


@contextmanager
def frame_pass(source: Iterable[Frame]) -> Iterator[Iterator[Frame]]:
    """One pass over a source's frames as a context: ``with frame_pass(source) as frames: for frame in
    frames``. The pass is closed when the block ends (its decoding threads stopped), also when it ends
    early or by an exception, not later by the garbage collector: a pass closed in a finalizer is one
    where Python only prints an exception raised meanwhile (a SIGTERM, SIGHUP or Ctrl-C turned into one
    by ``gnomon.cli``) and goes on, so the scan ran to its end and published."""
    frames = iter(source)
    try:
        yield frames
    finally:
        close = getattr(frames, "close", None)
        if close is not None:
            close()


ON_CORRUPT = ("error", "drop")
"""What a frame source does with a corrupt image file (``[capture] on_corrupt_frame``): refuse it, naming it
(:class:`~gnomon.errors.CorruptFrameError`), or leave it out and list it (:attr:`FrameSource.dropped`)."""


@dataclass(frozen=True)
class DroppedFrame:
    """A frame left out of a pass: its capture index, file name and why (the decoder's words)."""

    index: int
    name: str
    reason: str


def dropped_frames_warning(dropped: Sequence[DroppedFrame]) -> str:
    """The warning a scan gives for the corrupt frames it left out (each named, with the decoder's words)."""
    named = "; ".join(f"frame {d.index} ({d.name}): {d.reason}" for d in dropped[:5])
    more = f"; and {len(dropped) - 5} more" if len(dropped) > 5 else ""
    return (f"{len(dropped)} corrupt frame{'s' if len(dropped) > 1 else ''} left out ([capture] on_corrupt_frame "
            f"= \"drop\"): {named}{more}; the shadow's times are interpolated across the gap, less accurately "
            "on the pixels its edges crossed then: replace the files from the camera's card or a backup to use them")


class FrameSource:
    """A sequence of frames from an image list or a video file.

    ``expected_count``: when given, a source that delivers fewer frames raises
    :class:`FrameError` (a truncated video or a missing file is not a shorter scan).
    ``on_corrupt`` (:data:`ON_CORRUPT`): an image file whose data is corrupt inside
    (:func:`decode_jpeg`) raises :class:`~gnomon.errors.CorruptFrameError` naming it (``"error"``), or is
    left out of the pass and listed in :attr:`dropped` (``"drop"``: the frames after it keep their
    capture indices, so a tracker sees a gap in time there, as for a skipped frame).
    """

    def __init__(self, image_files: tuple[Path, ...] = (), video: Path | None = None,
                 expected_count: int | None = None, on_corrupt: str = "error"):
        if bool(image_files) == (video is not None):
            raise ValueError("give either image files or a video")
        if on_corrupt not in ON_CORRUPT:
            raise ValueError(f"on_corrupt {on_corrupt!r}: expected one of {ON_CORRUPT}")
        self.image_files = tuple(image_files)
        self.video = video
        self.expected_count = expected_count
        self.on_corrupt = on_corrupt
        # The corrupt frames the last pass left out (on_corrupt = "drop"), in order.
        self.dropped: list[DroppedFrame] = []
        # Frames delivered with their colour image too (besides grey): the first, and those a scan's
        # colours are taken from (gnomon.capture.texture.LitColour).
        self.color_frames: frozenset[int] = frozenset({0})
        # Threads decoding image files at once (None: decode_workers()).
        self.decode_threads: int | None = None
        # sha256 of every frame file's bytes, set when a pass has decoded them all (videos: see frames_digest).
        self._digest: str | None = None
        if video is not None:
            cap = cv2.VideoCapture(str(video))
            try:
                if not cap.isOpened():
                    raise FrameError(f"{video}: cannot be opened as a video")
                announced = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
                if expected_count is None and video.suffix.lower() not in EXACT_COUNT_SUFFIXES:
                    announced = _count_frames(cap)
                    if announced == 0:
                        raise FrameError(_undecodable(video, cap))
            finally:
                cap.release()
            self.count = expected_count if expected_count is not None else announced
            if self.count <= 1:
                raise FrameError(f"{video}: the video reports {announced} frames; a scan needs a sequence")
        else:
            self.count = len(self.image_files)

    def frames_digest(self) -> str:
        """sha256 of the input: all image files' bytes in order, or the video file.

        Taken from the last complete pass over the frames when there was one
        (the files are then read once), else from the files themselves.
        """
        if self.video is not None:
            return sha256_file(self.video)
        if self._digest is None:
            h = hashlib.sha256()
            for path in self.image_files:
                with open(path, "rb") as fh:
                    while block := fh.read(1 << 20):
                        h.update(block)
            return h.hexdigest()
        return self._digest

    @property
    def name(self) -> str:
        return str(self.video) if self.video is not None else str(self.image_files[0].parent)

    def _check_size(self, index: int, name: str, image: np.ndarray, first: np.ndarray | None) -> None:
        if first is not None:
            _check_like(index, name, image.shape, image.dtype, first.shape, first.dtype)

    def _decode(self) -> Iterator[Frame]:
        """A video's frames in order, on the reader thread (image files: :meth:`_decode_parallel`)."""
        first: np.ndarray | None = None
        video = self.video
        assert video is not None  # the image files decode in _decode_parallel
        cap = cv2.VideoCapture(str(video))
        try:
            i = 0
            while i < self.count:
                ok, image = cap.read()
                if (not ok or image is None) and i == 0:
                    raise FrameError(_undecodable(video, cap))
                if not ok or image is None:
                    raise FrameError(
                        f"{self.video}: the video ended after {i} frames, expected {self.count}"
                    )
                self._check_size(i, f"video frame {i}", image, first)
                if first is None:
                    first = image
                color = image[:, :, :3] if (i in self.color_frames and image.ndim == 3) else None
                yield Frame(i, to_grey(image), color, f"video frame {i}")
                i += 1
        finally:
            cap.release()

    def _decode_parallel(self) -> Iterator[Frame]:
        """The image files' frames in order, decoded on ``decode_threads`` threads at once (by default
        ``decode_workers()``).

        At most ``FRAMES_IN_FLIGHT`` frames are submitted and not yet taken. A file that
        fails to decode raises (its :class:`FrameError`) when its turn comes, after the
        frames before it; leaving early (an error, a peek at the first frame) cancels the
        frames not started and waits for those being decoded (no thread outlives the pass).

        The files' bytes are hashed in order on a thread of their own (hashlib releases the GIL),
        not on the consumer's (its time is the tracker's); leaving the pass waits for it.
        """
        colour = self.color_frames
        digest = hashlib.sha256()
        first: tuple[tuple[int, ...], np.dtype] | None = None
        pending: deque[Future[_Decoded]] = deque()
        files = enumerate(self.image_files)
        workers = self.decode_threads or decode_workers()
        drop = self.on_corrupt == "drop"
        self.dropped = []
        with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="gnomon-frame-decode") as pool, \
                ThreadPoolExecutor(max_workers=1, thread_name_prefix="gnomon-frame-digest") as hasher:
            try:
                # Start with one frame per thread (a peek decodes little more than the first),
                # then keep FRAMES_IN_FLIGHT ahead.
                for i, path in files:
                    pending.append(pool.submit(_decode_file, i, path, i in colour, drop))
                    if len(pending) >= workers:
                        break
                while pending:
                    decoded = pending.popleft().result()
                    for i, path in files:
                        pending.append(pool.submit(_decode_file, i, path, i in colour, drop))
                        if len(pending) >= FRAMES_IN_FLIGHT:
                            break
                    hasher.submit(digest.update, decoded.raw)  # one thread: in the files' order
                    if decoded.grey is None:  # corrupt, and dropped
                        self.dropped.append(DroppedFrame(decoded.index, decoded.name, decoded.corrupt))
                        continue
                    if first is None:
                        first = (decoded.grey.shape, decoded.grey.dtype)
                    else:
                        _check_like(decoded.index, decoded.name, decoded.grey.shape, decoded.grey.dtype, *first)
                    yield Frame(decoded.index, decoded.grey, decoded.color, decoded.name)
            finally:
                for job in pending:
                    job.cancel()
        self._digest = digest.hexdigest()

    def first(self) -> Frame:
        """The first frame alone (:class:`FrameError` when there is none).

        The pass is closed here, before returning: its decoding threads stop in this call, so a signal
        that arrives meanwhile (``gnomon.cli``'s SIGTERM/SIGHUP/SIGINT) is raised to the caller. Left to
        the garbage collector (a ``for`` loop left by ``return``), the pass is closed in a finalizer,
        where Python only prints such an exception and goes on: the scan then ran to its end."""
        with frame_pass(self) as frames:
            frame = next(frames, None)
        if frame is None:
            raise FrameError(f"{self.name}: no frames")
        return frame

    def __iter__(self) -> Iterator[Frame]:
        """Frames in order, decoded on background threads."""
        if self.video is None and type(self)._decode is FrameSource._decode:  # image files
            yield from self._decode_parallel()
            return
        yield from ahead(self._decode(), FRAMES_IN_FLIGHT, "gnomon-frame-reader", join_timeout=5)


@dataclass
class _Decoded:
    """One image file decoded on a decoding thread (its checks against the first frame are the consumer's)."""

    index: int
    name: str
    grey: np.ndarray | None  # its size and sample type are the file's; None: corrupt and dropped
    color: np.ndarray | None
    raw: bytes  # the file's bytes, for the input digest
    corrupt: str = ""  # why the file was dropped (the decoder's words)


CORRUPT_FRAME_HINT = ("replace it from the camera's card or a backup, or leave it out with [capture] "
                      "on_corrupt_frame = \"drop\"")


def _decode_file(index: int, path: Path, keep_colour: bool, drop: bool = False) -> _Decoded:
    """One image file decoded (on a decoding thread); a corrupt one, with ``drop``, as a :class:`_Decoded`
    without an image, otherwise a :class:`~gnomon.errors.CorruptFrameError` saying what the user can do."""
    try:
        grey, color, raw = decode_frame_file(path, keep_colour)
    except CorruptFrameError as exc:
        if not drop:
            raise CorruptFrameError(path, exc.reason, CORRUPT_FRAME_HINT) from None
        return _Decoded(index, path.name, None, None, path.read_bytes(), exc.reason)
    return _Decoded(index, path.name, grey, color, raw)


def _check_like(index: int, name: str, shape: tuple[int, ...], dtype: np.dtype,
                first_shape: tuple[int, ...], first_dtype: np.dtype) -> None:
    """A frame's size and sample type must be the first frame's."""
    if shape[:2] != first_shape[:2]:
        h, w = shape[:2]
        h0, w0 = first_shape[:2]
        raise FrameError(f"frame {index} ({name}): size {w}x{h} differs from the first frame's {w0}x{h0}")
    if dtype != first_dtype:
        raise FrameError(f"frame {index} ({name}): {dtype} samples, the first frame has {first_dtype}")
