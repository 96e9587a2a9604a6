"""Writes the EXIF test photos in crates/skydome/tests/data/exif/ the way stations write them.

Raspberry Pi sky cameras commonly tag their JPEGs with `piexif`; others with Pillow. Each file is
a 64 x 64 JPEG (a grey ramp) carrying the same capture fields: ExposureTime 1/250 s, FNumber 2.8,
ISO 100, DateTimeOriginal 2026:06:21 12:30:05, SubSecTimeOriginal 25, OffsetTimeOriginal +02:00,
GPS 47.5 N 8.25 E. Run once with `pip install piexif pillow` (versions in the commit that added
the files); the tests only read the files.

    python scripts/exif_fixtures.py crates/skydome/tests/data/exif
"""
import io
import sys

import piexif
from PIL import Image

OUT = sys.argv[1]


def ramp():
    img = Image.new("RGB", (64, 64))
    img.putdata([(4 * x, 4 * y, 128) for y in range(64) for x in range(64)])
    return img


def jpeg(img, **kw):
    b = io.BytesIO()
    img.save(b, "JPEG", quality=90, **kw)
    return b.getvalue()


def piexif_dict(thumbnail):
    d = {
        "0th": {
            piexif.ImageIFD.Make: b"Raspberry Pi",
            piexif.ImageIFD.Model: b"RP_imx477",
            piexif.ImageIFD.Orientation: 1,
        },
        "Exif": {
            piexif.ExifIFD.ExposureTime: (1, 250),
            piexif.ExifIFD.FNumber: (28, 10),
            piexif.ExifIFD.ISOSpeedRatings: 100,
            piexif.ExifIFD.DateTimeOriginal: b"2026:06:21 12:30:05",
            piexif.ExifIFD.SubSecTimeOriginal: b"25",
            piexif.ExifIFD.OffsetTimeOriginal: b"+02:00",
        },
        "GPS": {
            piexif.GPSIFD.GPSLatitudeRef: b"N",
            piexif.GPSIFD.GPSLatitude: ((47, 1), (30, 1), (0, 1)),
            piexif.GPSIFD.GPSLongitudeRef: b"E",
            piexif.GPSIFD.GPSLongitude: ((8, 1), (15, 1), (0, 1)),
        },
    }
    if thumbnail:
        small = ramp().resize((16, 16))
        d["1st"] = {piexif.ImageIFD.XResolution: (72, 1), piexif.ImageIFD.YResolution: (72, 1)}
        d["thumbnail"] = jpeg(small)
    return d


# piexif: EXIF inserted into a finished JPEG, without and with a thumbnail (IFD1).
for name, thumb in [("piexif_station.jpg", False), ("piexif_thumbnail.jpg", True)]:
    out = io.BytesIO()
    piexif.insert(piexif.dump(piexif_dict(thumb)), jpeg(ramp()), out)
    with open(f"{OUT}/{name}", "wb") as f:
        f.write(out.getvalue())

# Pillow: Image.Exif with the Exif and GPS sub-IFDs.
exif = Image.Exif()
exif[0x010F] = "Raspberry Pi"
exif[0x0110] = "RP_imx477"
exif[0x0112] = 1
sub = exif.get_ifd(0x8769)
sub[0x829A] = 1 / 250
sub[0x829D] = 2.8
sub[0x8827] = 100
sub[0x9003] = "2026:06:21 12:30:05"
sub[0x9291] = "25"
sub[0x9011] = "+02:00"
gps = exif.get_ifd(0x8825)
gps[1] = "N"
gps[2] = (47.0, 30.0, 0.0)
gps[3] = "E"
gps[4] = (8.0, 15.0, 0.0)
with open(f"{OUT}/pillow_station.jpg", "wb") as f:
    f.write(jpeg(ramp(), exif=exif.tobytes()))
