"""The scene dispatcher: a synthetic capture rendered by name (``gnomon simulate``, :func:`gnomon.simulate`).

It imports no scanning code: the simulator is an independent reference for the scanner.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from gnomon.errors import GnomonError
from gnomon.util import validate
from gnomon.util.progress import Progress

__all__ = ["SCENES", "simulate"]

#: Scenes :func:`simulate` (and `gnomon simulate`) can render.
SCENES = ("desk_lamp", "desk_lamp_right", "desk_turns", "two_plane", "room", "facade_sun", "facade_day", "chessboard")


def _scene_config(scene: str, options: dict[str, Any]) -> tuple[Any, Any]:
    """``(config, render)`` of a shadow-sweep scene from its options (the configuration's fields)."""
    make: Callable[..., Any]
    render: Callable[..., Any]
    if scene in ("desk_lamp", "desk_lamp_right"):
        from gnomon.simulate.desk_lamp import DeskLampConfig, simulate_desk_lamp

        if "lamp_side" in options:
            raise GnomonError(f"simulate {scene}: lamp_side is the scene's (desk_lamp: left, desk_lamp_right: right)")
        make, render = DeskLampConfig, simulate_desk_lamp
        options = {**options, "lamp_side": "left" if scene == "desk_lamp" else "right"}
    elif scene == "desk_turns":
        from gnomon.simulate.turntable import TurnsConfig, simulate_turns

        make, render = TurnsConfig, simulate_turns
    elif scene == "two_plane":
        from gnomon.simulate.two_plane_scene import TwoPlaneConfig, simulate_two_plane

        make, render = TwoPlaneConfig, simulate_two_plane
    elif scene == "room":
        from gnomon.simulate.room import RoomConfig, simulate_room

        make, render = RoomConfig, simulate_room
    else:
        from gnomon.simulate.facade_sun import FacadeSunConfig, simulate_facade_sun

        make = FacadeSunConfig.day if scene == "facade_day" else FacadeSunConfig
        render = simulate_facade_sun
        if options.get("roof_edge"):
            from gnomon.simulate.roof_edge import simulate_roof_edge

            render = simulate_roof_edge
    try:
        config = make(**options)
    except TypeError as exc:
        raise GnomonError(f"simulate {scene}: {exc}") from None
    config.validate()
    return config, render


def simulate(scene: str, out: str | os.PathLike, *, progress: bool = False, **options: Any) -> Path:
    """Render a synthetic capture with exact ground truth into ``out``; return its field log's path.

    ``scene`` one of :data:`SCENES` (`gnomon simulate --help` describes them).
    ``options`` are the scene's settings, the fields of its configuration:
    :class:`gnomon.simulate.DeskLampConfig` (``desk_lamp``, ``desk_lamp_right``),
    :class:`~gnomon.simulate.TwoPlaneConfig` (``two_plane``; ``markers="aruco"``
    for ArUco markers), :class:`~gnomon.simulate.FacadeSunConfig` (``facade_sun``;
    ``facade_day`` starts from ``FacadeSunConfig.day()``), e.g. ``width=400,
    height=300, frames=120, seed=1``; a setting left out keeps the scene's
    default. The folder gets ``frames/``, ``ground_truth.npz``,
    ``ground_truth.json`` and, last, ``field_log.toml`` (desk_lamp scenes also
    pencil photos and ``pencil_log.toml``). ``chessboard`` (options ``width``,
    ``height``, default 1280x960, and ``seed``) writes 12 views of a 9x6 board
    with 25 mm squares and the true camera instead, and returns the folder.
    ``progress`` a progress bar on stderr. `gnomon simulate` calls this
    function with its options; error messages name the command's options.
    """

    if scene not in SCENES:
        raise GnomonError(f"simulate: unknown scene {scene!r} (one of {', '.join(SCENES)})")
    validate.check_output_folder(out)
    if "seed" in options:
        validate.number(options["seed"], "--seed", minimum=0, maximum=2**32 - 1, integer=True)
    if scene == "chessboard":
        from gnomon.simulate.chessboard import default_truth_camera, write_chessboard_views

        options = dict(options)
        width, height, seed = options.pop("width", 1280), options.pop("height", 960), options.pop("seed", 0)
        if options:
            raise GnomonError(f"simulate chessboard: unknown options {sorted(options)} (width, height, seed)")
        write_chessboard_views(Path(out), camera=default_truth_camera(width, height), cols=9, rows=6, square=25.0,
                               n_views=12, seed=seed)
        return Path(out)
    config, render = _scene_config(scene, options)
    total = config.frames * getattr(config, "views", 1)
    with Progress("simulate", total, enabled=progress) as bar:
        result = render(out, config, progress=lambda done, total: bar.update(done))
    return Path(result.out_dir) if scene == "desk_turns" else Path(result.field_log)
