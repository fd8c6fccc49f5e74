"""The capture, from frames to shadow times: frames read and decoded on background threads
(:mod:`~gnomon.capture.frames`: image folders and videos), each frame's motion against the first measured
and undone (:mod:`~gnomon.capture.registration`), the streaming per-pixel shadow tracker over
the Rust kernel (:mod:`~gnomon.capture.tracking`), the image noise (:mod:`~gnomon.capture.noise`),
cloud dips levelled (:mod:`~gnomon.capture.cloud_levels`), a codec's blocks undone
(:mod:`~gnomon.capture.deblock`), the scan's colours from the lit frames (:mod:`~gnomon.capture.texture`,
:mod:`~gnomon.capture.colours`) and image tiles tracked on Dask workers (:mod:`~gnomon.capture.tiles`,
loaded on use).
"""

from gnomon.capture.frames import VIDEO_SUFFIXES, Frame, FrameSource, glob_frames, to_grey
from gnomon.capture.noise import image_noise_dn
from gnomon.capture.registration import FrameRegistrar, Registration
from gnomon.capture.texture import LitColour
from gnomon.capture.tracking import (
    MIN_CONTRAST_SIGMAS,
    SecondDips,
    ShadowTimes,
    ShadowTracker,
    TrackedSequence,
    TrackerSettings,
    decoding_lut,
    linear,
    track_source,
    track_widening,
)

__all__ = [
    "Frame", "FrameRegistrar", "FrameSource", "LitColour", "MIN_CONTRAST_SIGMAS", "Registration", "SecondDips",
    "ShadowTimes", "ShadowTracker", "TrackedSequence", "TrackerSettings", "VIDEO_SUFFIXES", "decoding_lut",
    "glob_frames", "image_noise_dn", "linear", "to_grey", "track_source", "track_widening",
]
