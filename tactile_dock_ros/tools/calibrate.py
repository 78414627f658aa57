"""Camera-to-plane extrinsic from one image of a ChArUco board at a known pose.

    python -m tactile_dock_ros.tools.calibrate IMAGE --K fx 0 cx 0 fy cy 0 0 1 \
        --board-pose board_pose.yaml --out config/perception_robot.yaml [--squares 7 5 ...]

``board_pose.yaml`` holds ``T_plane_board``: the board frame (origin at its top-left chessboard
corner, x along rows, y down, z into the board) in the docking-plane frame, a 4x4 list. The
``extrinsic`` section of ``--out`` is (re)written in the perception config format; any other
sections already in the file are kept.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np
import yaml

from ..perception.calibration import BoardSpec, calibrate_extrinsic
from ..perception.config import PerceptionError, extrinsic_to_dict


def _board_pose(path: Path) -> np.ndarray:
    """``T_plane_board`` (4, 4) from a YAML file; PerceptionError naming what is wrong."""
    document = yaml.safe_load(path.read_text())
    if not isinstance(document, dict) or "T_plane_board" not in document:
        raise PerceptionError(f"{path}: needs a key T_plane_board (a 4x4 list)")
    try:
        pose = np.asarray(document["T_plane_board"], dtype=float)
    except (TypeError, ValueError):
        pose = np.zeros(0)
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        raise PerceptionError(f"{path}: T_plane_board must be a finite 4x4 matrix")
    return pose


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("image", type=Path)
    parser.add_argument("--K", type=float, nargs=9, required=True, help="CameraInfo K, row-major")
    parser.add_argument("--board-pose", type=Path, required=True, help="YAML with T_plane_board")
    parser.add_argument("--out", type=Path, required=True, help="perception config YAML")
    parser.add_argument("--squares", type=int, nargs=2, default=(7, 5), metavar=("X", "Y"))
    parser.add_argument("--square-m", type=float, default=0.04)
    parser.add_argument("--marker-m", type=float, default=0.03)
    parser.add_argument("--dictionary", default="DICT_5X5_100")
    args = parser.parse_args(argv)
    image = cv2.imread(str(args.image), cv2.IMREAD_GRAYSCALE)
    if image is None:
        parser.error(f"cannot read image {args.image}")
    try:
        pose = _board_pose(args.board_pose)
        config = (yaml.safe_load(args.out.read_text()) if args.out.exists() else None) or {}
    except (OSError, yaml.YAMLError, PerceptionError) as err:
        parser.error(str(err))
    if not isinstance(config, dict):
        parser.error(f"--out {args.out} holds no perception config mapping")
    spec = BoardSpec(*args.squares, args.square_m, args.marker_m, args.dictionary)
    try:
        result = calibrate_extrinsic(image, np.reshape(args.K, (3, 3)), spec, pose)
    except PerceptionError as err:
        print(f"calibration failed: {err}", file=sys.stderr)
        return 1
    section = config["perception"] if "perception" in config else config
    section["extrinsic"] = extrinsic_to_dict(result.extrinsic)
    args.out.write_text(yaml.safe_dump(config, sort_keys=False))
    sigma = np.sqrt(np.diag(result.extrinsic.covariance))
    print(
        f"{result.corners} corners, reprojection RMS {result.reprojection_rms_px:.2f} px, "
        f"sigma t {np.round(sigma[:3] * 1e3, 2)} mm, r {np.round(np.rad2deg(sigma[3:]), 3)} deg"
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
