"""skydome: calibrated HDR radiance maps of the sky-dome from bracketed fish-eye photos.

The same core as the ``skydome`` command line and the phone app (the Rust library's
``skydome::pipeline::run``), with numpy arrays in and out:

>>> import skydome
>>> dome = skydome.run(["sky_-2.jpg", "sky_0.jpg", "sky_+2.jpg"], fisheye=True, crop=True)
>>> dome.radiance.shape, dome.radiance.dtype          # (H, W, 3) float32, linear radiance
>>> dome.report["geometry"]["sun"]                     # what `skydome merge --json` prints
>>> dome.save("dome.hdr")                              # the CLI's exact bytes

Conventions: arrays are indexed [y, x, channel] with row 0 at the top and channels R, G, B;
angles are degrees; azimuth from true north towards east; exposure times in seconds.
Errors raise :class:`skydome.Error` (a ValueError) with the command line's one-line message.
The GIL is released while the core computes. See docs/python.md in the repository.
"""

from ._skydome import (  # noqa: F401
    CameraProfile,
    Dome,
    Error,
    __version__,
    calibrate,
    read_hdr,
    run,
    tonemap,
    write_hdr,
)

__all__ = [
    "CameraProfile",
    "Dome",
    "Error",
    "__version__",
    "calibrate",
    "read_hdr",
    "run",
    "tonemap",
    "write_hdr",
]
