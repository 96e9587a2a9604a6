"""Type stubs of skydome (the native module skydome._skydome, re-exported here).

Conventions: arrays are indexed [y, x, channel], row 0 at the top, channels R, G, B; angles in
degrees; azimuth from true north towards east; exposure times in seconds; radiance linear,
relative units unless a luminance or illuminance reading made it absolute (Radiance's
W/sr/m2, luminance = 179 * (0.265 R + 0.670 G + 0.065 B) cd/m2).
"""

import os
from datetime import datetime
from typing import Any, Callable, Literal, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

PathLike = Union[str, "os.PathLike[str]"]
Frame = Union[PathLike, bytes, bytearray, memoryview, npt.NDArray[np.uint8], npt.NDArray[np.uint16]]
Frames = Union[Sequence[Frame], npt.NDArray[np.uint8], npt.NDArray[np.uint16]]
Stage = Literal["decoding", "lens", "calibrating", "merging", "sky", "pictures"]
Header = dict[str, Any]

class Error(ValueError):
    """A skydome job failed; the message is the command line's one line (file and problem)."""

class CameraProfile:
    """A camera's response curves: the command line's camera.json."""

    @staticmethod
    def load(path: PathLike) -> "CameraProfile":
        """Reads and validates a camera.json; skydome.Error names the file when it cannot."""
    @staticmethod
    def from_json(text: str) -> "CameraProfile": ...
    def save(self, path: PathLike) -> None:
        """Writes the profile as JSON, atomically."""
    def to_json(self) -> str: ...
    def to_dict(self) -> dict[str, Any]: ...
    @property
    def g(self) -> npt.NDArray[np.float64]:
        """(3, 256): g_c(Z) = ln E + ln dt for codes Z = 0..255, channels R, G, B."""
    @property
    def linear(self) -> bool: ...
    @property
    def make(self) -> Optional[str]: ...
    @property
    def model(self) -> Optional[str]: ...
    @property
    def iso(self) -> Optional[float]: ...
    @property
    def date(self) -> Optional[str]: ...
    @property
    def lambda_(self) -> float:
        """Smoothness weight the curves were solved with."""
    @property
    def samples(self) -> int: ...
    @property
    def seed(self) -> int: ...
    def __eq__(self, other: object) -> bool: ...

class Dome:
    """The result of run(): radiance, header, report and the products asked for."""

    @property
    def radiance(self) -> npt.NDArray[np.float32]:
        """(height, width, 3) linear radiance, a read-only view (no copy)."""
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def report(self) -> dict[str, Any]:
        """What `skydome merge --json` prints (less `written`)."""
    @property
    def header(self) -> Header:
        """exposure, capdate, gmt, view, sun {pixel {x, y}, azimuth_deg, elevation_deg}, north {x, y}, software, other."""
    @property
    def preview(self) -> Optional[npt.NDArray[np.uint8]]:
        """(height, width, 3) sRGB preview when run(preview=True), read-only view."""
    @property
    def equirect(self) -> Optional[npt.NDArray[np.float32]]:
        """(height, 2*height, 3) lat-long map when run(equirect=...): east at the centre, north at a quarter."""
    @property
    def camera_profile(self) -> Optional[CameraProfile]:
        """The profile calibrated on this bracket (None when a profile was given)."""
    def save(
        self,
        path: PathLike,
        *,
        exr_float: bool = False,
        exr_compression: Literal["zip", "piz", "zips", "rle", "none"] = "zip",
    ) -> None:
        """Writes .hdr (the CLI's exact bytes) or .exr by extension, atomically."""
    def save_equirect(
        self,
        path: PathLike,
        *,
        exr_float: bool = False,
        exr_compression: Literal["zip", "piz", "zips", "rle", "none"] = "zip",
    ) -> None: ...

def run(
    frames: Frames,
    times: Optional[Sequence[float]] = None,
    *,
    profile: Union[CameraProfile, PathLike, None] = None,
    lens: Union[PathLike, dict[str, Any], None] = None,
    fisheye: bool = False,
    lens_model: Optional[Literal["stereographic", "equidistant", "equisolid", "orthographic"]] = None,
    fov: Optional[float] = None,
    crop: bool = False,
    sun: Union[Literal["auto", "none", "ephemeris"], Tuple[float, float], None] = "auto",
    north: Union[float, Literal["from-sun"], None] = None,
    time: Union[str, datetime, None] = None,
    lat: Optional[float] = None,
    lon: Optional[float] = None,
    illuminance: Optional[float] = None,
    luminance: Union[Tuple[float, float, float], Tuple[float, float, float, float], None] = None,
    weighting: Literal["hat", "noise", "none"] = "noise",
    exposures: Literal["listed", "measured"] = "listed",
    preview: bool = False,
    equirect: Union[bool, int, None] = None,
    progress: Optional[Callable[[Stage, float], Any]] = None,
    circle: Optional[Tuple[float, float, float]] = None,
) -> Dome:
    """Runs the whole sky-dome job on a bracket, as `skydome merge` (see help(skydome.run))."""

def calibrate(
    frames: Frames,
    times: Optional[Sequence[float]] = None,
    *,
    samples: Optional[int] = None,  # 100
    grid: int = 10,
    seed: int = 0,
    code_bands: int = 16,
    lambda_: Optional[float] = None,  # 30
    method: Literal["auto", "robust", "covering", "seed"] = "auto",
    solver: Literal["schur", "svd"] = "schur",
    circle: Optional[Tuple[float, float, float]] = None,
    linear: bool = False,
    progress: Optional[Callable[[Stage, float], Any]] = None,
) -> CameraProfile:
    """Calibrates the camera response on a bracket, as `skydome calibrate`."""

def read_hdr(path: PathLike) -> Tuple[npt.NDArray[np.float32], Header]:
    """Reads .hdr or .exr: (radiance (H, W, 3) float32 divided by EXPOSURE, header dict)."""

def write_hdr(
    path: PathLike,
    array: Union[npt.NDArray[np.float32], npt.NDArray[np.float64]],
    header: Optional[Header] = None,
) -> None:
    """Writes .hdr or .exr by extension, atomically; stored = radiance * header['exposure']."""

def tonemap(
    array: Union[npt.NDArray[np.float32], npt.NDArray[np.float64]],
    op: Literal["aces", "reinhard", "drago", "linear", "minmax"] = "aces",
    *,
    exposure: Optional[float] = None,
    key: float = 0.18,
    white_percentile: float = 99.5,
    bias: float = 0.85,
    circle: Optional[Tuple[float, float, float]] = None,
    whole_frame: bool = False,
    bits: Literal[8, 16] = 8,
) -> Union[npt.NDArray[np.uint8], npt.NDArray[np.uint16]]:
    """Tone-maps radiance to sRGB, as `skydome tonemap` (ACES, automatic exposure by default)."""
