"""ChArUco calibration targets: the board's description, its image, and its file (``board.yaml``)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml
from numpy.typing import NDArray

from rigctl.errors import RigFileError
from rigctl.publish import publish_text
from rigctl.yamlfile import load_yaml

DICTIONARIES = {
    "DICT_4X4_250": cv2.aruco.DICT_4X4_250,
    "DICT_5X5_250": cv2.aruco.DICT_5X5_250,
    "DICT_6X6_250": cv2.aruco.DICT_6X6_250,
}


@dataclass(frozen=True)
class BoardSpec:
    """A ChArUco board: squares across and down, square and marker size in metres, ArUco dictionary."""

    squares_x: int = 8
    squares_y: int = 6
    square_m: float = 0.075
    marker_m: float = 0.055
    dictionary: str = "DICT_5X5_250"

    @property
    def size_m(self) -> tuple[float, float]:
        return self.squares_x * self.square_m, self.squares_y * self.square_m

    def board(self) -> cv2.aruco.CharucoBoard:
        if self.dictionary not in DICTIONARIES:
            raise RigFileError(f"board dictionary {self.dictionary!r} unknown (known: {', '.join(DICTIONARIES)})")
        dic = cv2.aruco.getPredefinedDictionary(DICTIONARIES[self.dictionary])
        return cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), self.square_m, self.marker_m, dic)

    def image(self, px_per_square: int, margin_px: int = 0) -> NDArray[np.uint8]:
        """The board as a greyscale image, ``px_per_square`` pixels per square, plus a white margin."""
        w = self.squares_x * px_per_square + 2 * margin_px
        h = self.squares_y * px_per_square + 2 * margin_px
        return np.asarray(self.board().generateImage((w, h), marginSize=margin_px, borderBits=1), dtype=np.uint8)

    def corners_m(self) -> NDArray[np.float64]:
        """Inner chessboard corners in board coordinates (x right, y down, z = 0), metres, N x 3."""
        return np.asarray(self.board().getChessboardCorners(), dtype=np.float64).reshape(-1, 3)

    def as_dict(self) -> dict[str, Any]:
        return {"spec": 1, "type": "charuco", **asdict(self)}

    def save(self, path: Path, exists: str | None = None) -> None:
        """Published whole; ``exists``: never over an existing file (the refusal's text, see ``publishing``)."""
        publish_text(path, yaml.safe_dump(self.as_dict(), sort_keys=False), exists)

    @classmethod
    def load(cls, path: Path) -> BoardSpec:
        data = load_yaml(path)
        if not isinstance(data, dict) or data.get("type") != "charuco":
            raise RigFileError(f"{path}: not a board description (type: charuco)")
        fields = {k: data[k] for k in ("squares_x", "squares_y", "square_m", "marker_m", "dictionary") if k in data}
        spec = cls(**fields)
        problem = spec.problem()
        if problem:  # held to what rigctl board makes: OpenCV hung on 100000 squares, raised on the rest
            raise RigFileError(f"{path}: {problem}")
        return spec

    def problem(self) -> str | None:
        """What makes no board, as ``field: why`` (the bounds ``rigctl board`` holds its options to), or None."""
        for key in ("squares_x", "squares_y"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int) or not 3 <= v <= 40:
                return f"{key}: must be a whole number of squares 3 to 40, got {v!r:.60}"
        if self.squares_x * self.squares_y // 2 > 250:
            return f"squares_x, squares_y: {self.squares_x}x{self.squares_y} needs more markers than a dictionary's 250"
        for key in ("square_m", "marker_m"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int | float) or not 1e-4 <= v <= 1.0:  # NaN fails too
                return f"{key}: must be a length of 0.0001 to 1 m, got {v!r:.60}"
        if not self.marker_m < self.square_m:
            return f"marker_m: {self.marker_m:g} must be smaller than square_m {self.square_m:g}"
        if self.dictionary not in DICTIONARIES:
            return f"dictionary: {self.dictionary!r:.60} unknown (known: {', '.join(DICTIONARIES)})"
        return None
