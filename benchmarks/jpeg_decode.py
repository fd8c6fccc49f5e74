"""The cost of decoding JPEG frames strictly (a script, not a test).

    PYTHONPATH=python python benchmarks/jpeg_decode.py [--width 1920 --height 1080] [--repeat 200] [FILES...]

Times, on the same frames, alternating so that both see the same machine load: OpenCV's decode of a
frame as a scan read it before (``cv2.imdecode``: the luma alone, or the colour image), and
:func:`gnomon.capture.frames.decode_jpeg` (libjpeg-turbo through simplejpeg, stopping on the decoder's
warnings), and checks that both give the same pixels. Without FILES it encodes a 1080p frame like a
phone's (textured colour, quality 90, 4:2:0). Prints the median time per frame of each, per kind.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "python"))

from gnomon.capture.frames import decode_jpeg  # noqa: E402


def phone_like_frame(width: int, height: int) -> bytes:
    """A textured colour 1080p-like frame (a desk, a wall, noise), encoded as a phone does (q90, 4:2:0)."""
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    base = 90 + 60 * np.sin(xx / 37.0) * np.cos(yy / 23.0) + 40 * (yy / height)
    bgr = np.stack([base * 0.8, base, base * 1.1], axis=-1) + rng.normal(0, 6, (height, width, 3))
    ok, buf = cv2.imencode(".jpg", np.clip(bgr, 0, 255).astype(np.uint8), [cv2.IMWRITE_JPEG_QUALITY, 90])
    assert ok
    return buf.tobytes()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", type=Path)
    ap.add_argument("--width", type=int, default=1920)
    ap.add_argument("--height", type=int, default=1080)
    ap.add_argument("--repeat", type=int, default=200)
    args = ap.parse_args()
    frames = [p.read_bytes() for p in args.files] or [phone_like_frame(args.width, args.height)]
    grey_flags = cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH | cv2.IMREAD_IGNORE_ORIENTATION
    kinds = {
        "grey (every frame)": (lambda raw: cv2.imdecode(np.frombuffer(raw, np.uint8), grey_flags),
                               lambda raw: decode_jpeg(Path("frame.jpg"), raw, colour=False)),
        "colour (the few kept in colour)": (lambda raw: cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_COLOR),
                                            lambda raw: decode_jpeg(Path("frame.jpg"), raw, colour=True)),
    }
    h, w = cv2.imdecode(np.frombuffer(frames[0], np.uint8), grey_flags).shape
    print(f"{len(frames)} frame(s) of {w}x{h}, {np.mean([len(f) for f in frames]) / 1e3:.0f} kB; "
          f"{args.repeat} decodes each, alternating")
    for kind, (opencv, strict) in kinds.items():
        for raw in frames:
            a, b = opencv(raw), strict(raw)
            assert b is not None and np.array_equal(a, b), "the strict decoder's pixels differ from OpenCV's"
        times: dict[str, list[float]] = {"opencv": [], "strict": []}
        for k in range(args.repeat):
            raw = frames[k % len(frames)]
            for name, fn in (("opencv", opencv), ("strict", strict)):
                t = time.perf_counter()
                fn(raw)
                times[name].append(time.perf_counter() - t)
        o, s = statistics.median(times["opencv"]) * 1e3, statistics.median(times["strict"]) * 1e3
        print(f"{kind:32s} OpenCV {o:6.2f} ms   strict {s:6.2f} ms   ({s - o:+.2f} ms, x{s / o:.2f}); same pixels")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
