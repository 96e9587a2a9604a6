#!/usr/bin/env python3
"""Radiance skies with known suns, for the sun-detection sweep (issue 22).

Renders upward angular fish-eyes (``rpict -vta``, 180° or 190°) of Perez skies made by
``gendaylit`` — Radiance from the ``pyradiance`` package on PyPI — with, in some scenes, a bright
cloud over the sun or elsewhere, and trees or buildings on the horizon. Each scene goes into its
own folder ``OUT/<name>-<key>/`` as

- ``truth.hdr``: absolute radiance (W·sr⁻¹·m⁻², Radiance's RGB), ``SIZE²``, north up, east
  left, rendered at 4× the size and box-averaged so the 0.533° solar disc is area-weighted;
- ``truth.json``: what the sky was made of — the sun's direction (azimuth from north towards east,
  elevation, degrees; from gendaylit's own output), its luminance, whether it is visible (not
  behind a cloud or an obstacle), gendaylit's inputs (direct normal and diffuse horizontal
  illuminance, lux), the lens's field of view, the camera settings the Rust side photographs it
  with (exposure offset, frame EVs, seed), the capture time and site when the scene has them,
  and the split (``tune`` or ``held-out``).

``key`` is a hash of the scene's parameters and this script's version, so a folder is rendered
once and re-rendered only when something that shapes it changes (the cache lives under
``target/``). The camera simulation (exposure, noise, response, JPEG) is the project's own,
``skydome::synth::photograph``, applied by the Rust harness
(``crates/skydome/tests/sun_sweep.rs``) to ``truth.hdr``.

Sets (``--set``):
- ``sweep``: 72 scenes, solar elevation 3–90° × azimuth × sky (clear, hazy, overcast,
  intermediate; a cloud over the sun; clouds elsewhere) × horizon (open, trees, buildings) ×
  exposure × frame count × lens 180°/190°, split by a fixed seed (22) into a ``tune`` half and a
  ``held-out`` half; ``--split tune|held-out`` renders one half only;
- ``day``: one station's day, 21 June 2026 at 47.05° N 8.31° E (UTC+02:00), one capture an hour
  from 06:00 to 21:00, a 190° lens, trees to the west, a cloud over the sun at 09, 13 and 17 h;
- ``issue``: the issue's case (sun at 10° elevation, azimuth 250°, direct normal 40 klx, diffuse
  9 klx, 512² dome).

Usage: ``python scripts/radiance_sweep.py --out target/radiance-sweep --set sweep [--split
held-out] [--jobs 1]``; prints one line per scene (``cached`` or the render time) and, at the
end, the folders written. Renders run under ``nice -n 19``.
"""

import argparse
import datetime as dt
import hashlib
import json
import math
import os
import random
import subprocess
import sys
import tempfile
import time

import numpy as np

VERSION = 4  # bump to re-render every cached scene
FINE = 4


def radiance_dirs():
    import pyradiance

    base = os.path.dirname(pyradiance.__file__)
    return os.path.join(base, "bin"), os.path.join(base, "lib")


BIN, LIB = radiance_dirs()


def run(prog, args, cwd, stdin=None):
    p = subprocess.run(
        ["nice", "-n", "19", os.path.join(BIN, prog)] + [str(a) for a in args],
        cwd=cwd,
        env=dict(os.environ, RAYPATH=LIB),
        input=stdin,
        capture_output=True,
    )
    if p.returncode != 0:
        raise RuntimeError(f"{prog} {args}: {p.stderr.decode(errors='replace')}")
    return p.stdout


# ---------------------------------------------------------------------------------------------
# Geometry helpers (ENU: x east, y north, z up; azimuth from north towards east).


def vec(az_deg, el_deg):
    a, e = math.radians(az_deg), math.radians(el_deg)
    return (math.cos(e) * math.sin(a), math.cos(e) * math.cos(a), math.sin(e))


def angle_between(u, v):
    d = sum(a * b for a, b in zip(u, v))
    return math.degrees(math.acos(max(-1.0, min(1.0, d))))


def direction(v):
    x, y, z = v
    return (math.degrees(math.atan2(x, y)) % 360.0, math.degrees(math.atan2(z, math.hypot(x, y))))


# ---------------------------------------------------------------------------------------------
# Sun position (NOAA's solar calculator, after Meeus; ~0.01° for 1800–2100) with the standard
# refraction correction, so the rendered sun is the apparent one a photo shows.


def sun_position(when, lat, lon):
    utc = when.astimezone(dt.timezone.utc)
    jd = utc.timestamp() / 86400.0 + 2440587.5
    t = (jd - 2451545.0) / 36525.0
    l0 = (280.46646 + t * (36000.76983 + t * 0.0003032)) % 360
    m = 357.52911 + t * (35999.05029 - 0.0001537 * t)
    e = 0.016708634 - t * (0.000042037 + 0.0000001267 * t)
    mr = math.radians(m)
    c = (
        math.sin(mr) * (1.914602 - t * (0.004817 + 0.000014 * t))
        + math.sin(2 * mr) * (0.019993 - 0.000101 * t)
        + math.sin(3 * mr) * 0.000289
    )
    true_long = l0 + c
    omega = 125.04 - 1934.136 * t
    app_long = true_long - 0.00569 - 0.00478 * math.sin(math.radians(omega))
    eps0 = 23 + (26 + (21.448 - t * (46.815 + t * (0.00059 - t * 0.001813))) / 60) / 60
    eps = eps0 + 0.00256 * math.cos(math.radians(omega))
    decl = math.degrees(
        math.asin(math.sin(math.radians(eps)) * math.sin(math.radians(app_long)))
    )
    y = math.tan(math.radians(eps / 2)) ** 2
    l0r = math.radians(l0)
    eqt = 4 * math.degrees(
        y * math.sin(2 * l0r)
        - 2 * e * math.sin(mr)
        + 4 * e * y * math.sin(mr) * math.cos(2 * l0r)
        - 0.5 * y * y * math.sin(4 * l0r)
        - 1.25 * e * e * math.sin(2 * mr)
    )
    minutes = utc.hour * 60 + utc.minute + utc.second / 60
    tst = (minutes + eqt + 4 * lon) % 1440
    ha = tst / 4 - 180
    latr, dr, har = math.radians(lat), math.radians(decl), math.radians(ha)
    cosz = math.sin(latr) * math.sin(dr) + math.cos(latr) * math.cos(dr) * math.cos(har)
    zen = math.degrees(math.acos(max(-1, min(1, cosz))))
    el = 90 - zen
    az = (
        math.degrees(
            math.atan2(
                math.sin(har),
                math.cos(har) * math.sin(latr) - math.tan(dr) * math.cos(latr),
            )
        )
        + 180
    ) % 360
    # Refraction (Bennett/Saemundsson as in NOAA's sheet), degrees.
    if el > 85:
        r = 0
    elif el > 5:
        te = math.tan(math.radians(el))
        r = (58.1 / te - 0.07 / te**3 + 0.000086 / te**5) / 3600
    elif el > -0.575:
        r = (1735 + el * (-518.2 + el * (103.4 + el * (-12.79 + el * 0.711)))) / 3600
    else:
        r = (-20.772 / math.tan(math.radians(el))) / 3600
    return az, el + r


# ---------------------------------------------------------------------------------------------
# Illuminance of clear, hazy, intermediate and overcast skies (lux): the IES clear-sky direct
# normal 127.5 klx·exp(−c·m) with c = 0.21 (clear), 0.30 (hazy), the Kasten–Young air mass m.


def air_mass(el):
    return 1 / (math.sin(math.radians(el)) + 0.50572 * (el + 6.07995) ** -1.6364)


def illuminance(kind, el):
    s = math.sin(math.radians(el))
    clear_dh = 800 + 15500 * math.sqrt(s)
    if kind == "clear":
        return 127500 * math.exp(-0.21 * air_mass(el)), clear_dh
    if kind == "hazy":
        return 127500 * math.exp(-0.30 * air_mass(el)), 1.5 * clear_dh
    if kind == "intermediate":
        return 0.45 * 127500 * math.exp(-0.25 * air_mass(el)), 2.0 * clear_dh
    if kind == "overcast":
        return 0.0, 1000 + 22000 * s
    raise ValueError(kind)


# ---------------------------------------------------------------------------------------------
# Scene description.


def tri(modifier, name, pts):
    coords = " ".join(f"{c:.5f}" for p in pts for c in p)
    return f"{modifier} polygon {name}\n0\n0\n9 {coords}\n"


def on_sphere(az, el, dist):
    v = vec(az, el)
    return tuple(dist * c for c in v)


def obstacle_rad(obs, dh):
    """Trees or buildings: strips at 100 m from -2° up to a top elevation that varies with
    azimuth; a glow of a dark surface lit by the diffuse sky (luminance ρ·E_dh/π)."""
    out = []
    rho = 0.08 if obs["kind"] == "trees" else 0.25
    rad = rho * dh / math.pi / 179.0
    col = (0.8, 1.0, 0.7) if obs["kind"] == "trees" else (1.0, 1.0, 1.0)
    out.append(
        f"void glow obstacle_mat\n0\n0\n4 {rad*col[0]:.6g} {rad*col[1]:.6g} {rad*col[2]:.6g} 0\n"
    )
    for i, (a0, a1, top) in enumerate(obs_profile(obs)):
        p = [
            on_sphere(a0, -3, 100),
            on_sphere(a1, -3, 100),
            on_sphere(a1, top, 100),
            on_sphere(a0, top, 100),
        ]
        out.append(tri("obstacle_mat", f"obs{i}a", [p[0], p[1], p[2]]))
        out.append(tri("obstacle_mat", f"obs{i}b", [p[0], p[2], p[3]]))
    return "".join(out)


def obs_profile(obs):
    """(azimuth from, azimuth to, top elevation) strips, 1° wide."""
    rng = random.Random(obs["seed"])
    strips = []
    a = obs["from"]
    while a < obs["to"]:
        if obs["kind"] == "trees":
            top = obs["height"] * (0.55 + 0.45 * abs(math.sin(a * 0.7))) + rng.uniform(-1, 1)
        else:
            top = obs["height"] if int((a - obs["from"]) // 12) % 3 != 2 else 0.6 * obs["height"]
        strips.append((a, a + 1.0, max(top, 0.5)))
        a += 1.0
    return strips


def obstacle_top(obs, az):
    for a0, a1, top in obs_profile(obs):
        if a0 <= az % 360 < a1 or a0 <= az % 360 + 360 < a1:
            return top
    return -90.0


def cloud_rad(clouds, dh):
    """Bright clouds: glow discs at 1 km facing the viewpoint, each a core and a brighter rim
    (the lit edge), luminance given as a multiple of E_dh/π."""
    out = []
    for i, c in enumerate(clouds):
        lum = c["brightness"] * dh / math.pi
        n = vec(c["az"], c["el"])
        centre = tuple(1000 * x for x in n)
        r = 1000 * math.tan(math.radians(c["radius"]))
        for part, (r0, r1, k) in enumerate([(0.0, 0.8, 1.0), (0.8, 1.0, c.get("rim", 1.3))]):
            rad = lum * k / 179.0
            out.append(f"void glow cloud{i}_{part}\n0\n0\n4 {rad:.6g} {rad:.6g} {rad:.6g} 0\n")
            out.append(
                f"cloud{i}_{part} ring cloud{i}_{part}s\n0\n0\n8 "
                f"{centre[0]:.4f} {centre[1]:.4f} {centre[2]:.4f} {-n[0]:.6f} {-n[1]:.6f} {-n[2]:.6f} "
                f"{r0 * r:.4f} {r1 * r:.4f}\n"
            )
    return "".join(out)


def numbers_after(text, key):
    at = text.index(key)
    tok = text[at + len(key) :].split()
    n = int(tok[2])
    return [float(t) for t in tok[3 : 3 + n]]


def write_rgbe(path, img):
    """Flat (uncompressed) Radiance RGBE, which every reader takes."""
    h, w, _ = img.shape
    m = img.max(axis=2)
    e = np.zeros(m.shape, dtype=np.int32)
    mant, ex = np.frexp(np.where(m > 1e-32, m, 1.0))
    e = np.where(m > 1e-32, ex, -128)
    scale = np.where(m > 1e-32, mant * 256.0 / np.where(m > 1e-32, m, 1.0), 0.0)
    rgbe = np.zeros((h, w, 4), dtype=np.uint8)
    rgbe[..., :3] = np.clip(np.floor(img * scale[..., None]), 0, 255).astype(np.uint8)
    rgbe[..., 3] = np.clip(e + 128, 0, 255).astype(np.uint8)
    rgbe[m <= 1e-32] = 0
    with open(path + ".tmp", "wb") as f:
        f.write(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\nSOFTWARE=radiance_sweep.py\n\n")
        f.write(f"-Y {h} +X {w}\n".encode())
        f.write(rgbe.tobytes())
    os.replace(path + ".tmp", path)


def render(scene, folder):
    dn, dh = scene["direct_normal_lux"], scene["diffuse_horizontal_lux"]
    az, el = scene["sun_request"]
    with tempfile.TemporaryDirectory() as tmp:
        # gendaylit refuses some direct/diffuse pairs near the horizon ("error sky", all
        # zeros): nudge the direct part until it accepts, and record what was used.
        for k in [1.0, 0.95, 1.05, 0.9, 1.1, 0.85, 1.15, 0.8, 1.25, 0.7, 1.4, 0.6]:
            desc = run(
                "gendaylit",
                ["-ang", el, az - 180.0, "-L", dn * k, dh],
                tmp,
            ).decode()
            tok = desc[desc.index("perezlum.cal") + 12 :].split()
            sky = [float(t) for t in tok[2 : 2 + int(tok[1])]]
            if any(abs(x) > 0 for x in sky[:2]):
                dn *= k
                break
        else:
            raise RuntimeError(f"gendaylit makes no sky for {scene['name']}")
        if dn > 0:
            solar = numbers_after(desc, "light solar")
            sun_lum = 179.0 * (0.265 * solar[0] + 0.670 * solar[1] + 0.065 * solar[2])
            s = numbers_after(desc, "source sun")
            sun_az, sun_el = direction(s[:3])
        else:
            sun_lum = 0.0
            sun_az, sun_el = az, el
        text = desc + (
            "\nskyfunc glow skyglow\n0\n0\n4 1 1 1 0\n\nskyglow source skydome\n0\n0\n4 0 0 1 180\n"
            "\nskyfunc glow groundglow\n0\n0\n4 1 1 1 0\n\ngroundglow source ground\n0\n0\n4 0 0 -1 180\n"
        )
        for obs in scene["obstacles"]:
            text += obstacle_rad(obs, dh)
        text += cloud_rad(scene["clouds"], dh)
        with open(os.path.join(tmp, "sky.rad"), "w") as f:
            f.write(text)
        oct_ = run("oconv", ["sky.rad"], tmp)
        with open(os.path.join(tmp, "sky.oct"), "wb") as f:
            f.write(oct_)
        n = scene["size"] * FINE
        fov = scene["fov_deg"]
        raw = run(
            "rpict",
            ["-vta", "-vp", 0, 0, 0, "-vd", 0, 0, 1, "-vu", 0, 1, 0, "-vh", fov, "-vv", fov,
             "-x", n, "-y", n, "-ps", 1, "-pj", 0, "-ab", 0, "sky.oct"],
            tmp,
        )
        floats = run("pvalue", ["-h", "-H", "-df", "-o"], tmp, stdin=raw)
    img = np.frombuffer(floats, dtype=np.float32).reshape(n, n, 3).astype(np.float64)
    size = scene["size"]
    img = img.reshape(size, FINE, size, FINE, 3).mean(axis=(1, 3))
    # Visibility of the 0.533° disc: hidden when a cloud or an obstacle covers all of it,
    # "partial" when it covers some of it (not scored either way), visible otherwise.
    sv = vec(sun_az, sun_el)
    hidden_by, partial = None, False
    for c in scene["clouds"]:
        d = angle_between(sv, vec(c["az"], c["el"]))
        if d < c["radius"] - 0.3:
            hidden_by = "cloud"
        elif d < c["radius"] + 0.3:
            partial = True
    for obs in scene["obstacles"]:
        top = obstacle_top(obs, sun_az)
        if sun_el < top - 0.3:
            hidden_by = "obstacle"
        elif sun_el < top + 0.3:
            partial = True
    rendered = dict(
        sun_azimuth_deg=sun_az,
        sun_elevation_deg=sun_el,
        sun_luminance_cd_m2=sun_lum,
        direct_normal_lux=dn,
        sun_visible=dn > 0 and hidden_by is None and not partial,
        sun_partly_hidden=dn > 0 and hidden_by is None and partial,
        hidden_by=hidden_by,
    )
    os.makedirs(folder, exist_ok=True)
    write_rgbe(os.path.join(folder, "truth.hdr"), img.astype(np.float32))
    write_json(os.path.join(folder, "render.json"), rendered)


def write_json(path, value):
    with open(path + ".tmp", "w") as f:
        json.dump(value, f, indent=1, sort_keys=True)
    os.replace(path + ".tmp", path)


# ---------------------------------------------------------------------------------------------
# The sets.

FRAME_SETS = {2: [-1.5, 1.5], 3: [-2.0, 0.0, 2.0], 4: [-4.0, -2.0, 0.0, 2.0], 5: [-6.0, -4.0, -2.0, 0.0, 2.0]}


def sweep_scenes():
    rng = random.Random(2222)
    elevations = [3, 4, 5, 7, 10, 13, 17, 25, 35, 50, 65, 88]
    kinds = ["clear", "hazy", "clear", "intermediate", "clear", "hazy"]
    scenes = []
    for i in range(72):
        el = elevations[i % len(elevations)] + rng.uniform(-0.4, 0.4)
        az = rng.uniform(0, 360)
        kind = kinds[(i // len(elevations)) % len(kinds)]
        variant = i % 6
        clouds, obstacles = [], []
        if (i // 3) % 8 == 5:
            kind = "overcast"
        if variant == 1 and kind != "overcast":
            # A bright cloud over the sun: the sun is hidden.
            r = rng.uniform(4, 9)
            off = rng.uniform(0, r - 2)
            t = rng.uniform(0, 360)
            caz = az + off * math.sin(math.radians(t)) / max(math.cos(math.radians(el)), 0.2)
            cel = min(el + off * math.cos(math.radians(t)), 89.0)
            clouds.append(dict(az=caz, el=cel, radius=r, brightness=rng.uniform(3, 12), rim=1.4))
        if variant in (2, 4):
            # Bright clouds elsewhere: a clipped cloud is not a sun.
            for _ in range(rng.randint(1, 3)):
                clouds.append(
                    dict(
                        az=rng.uniform(0, 360),
                        el=rng.uniform(8, 70),
                        radius=rng.uniform(3, 10),
                        brightness=rng.uniform(2, 8),
                        rim=rng.uniform(1.1, 1.6),
                    )
                )
            # Keep them off the sun.
            clouds = [c for c in clouds if angle_between(vec(c["az"], c["el"]), vec(az, el)) > c["radius"] + 4]
        if variant in (3, 4, 5):
            okind = "trees" if i % 2 else "buildings"
            height = rng.uniform(4, 14)
            # Around the sun's azimuth or away from it; a low sun behind them in some.
            centre = az + (rng.uniform(-20, 20) if variant != 4 else rng.uniform(60, 300))
            width = rng.uniform(40, 140)
            obstacles.append(
                dict(kind=okind, seed=i, height=height, **{"from": centre - width / 2, "to": centre + width / 2})
            )
        dn, dh = illuminance(kind, el)
        frames = [3, 3, 2, 3, 5, 3][(i // 2) % 6]
        scenes.append(
            dict(
                name=f"sweep{i:02d}",
                set="sweep",
                sun_request=[az, el],
                sky=kind,
                direct_normal_lux=dn,
                diffuse_horizontal_lux=dh,
                clouds=clouds,
                obstacles=obstacles,
                fov_deg=[180.0, 190.0][(i // 4) % 2],
                size=[256, 320, 384][i % 3],
                camera=dict(ev_offset=[0.0, -1.0, 1.0, 0.5][(i // 5) % 4], evs=FRAME_SETS[frames], seed=1000 + i),
                time=None,
                latitude_deg=None,
                longitude_deg=None,
            )
        )
    # The split: a fixed shuffle (seed 22); the first half tunes, the second is held out.
    order = list(range(len(scenes)))
    random.Random(22).shuffle(order)
    for rank, idx in enumerate(order):
        scenes[idx]["split"] = "tune" if rank < len(scenes) // 2 else "held-out"
    return scenes


FRESH_SEED = 2211
FRESH_BANDS = [(3.0, 5.0), (5.0, 10.0), (10.0, 20.0), (20.0, 45.0), (45.0, 90.0)]


HOLDOUT_SEED = 2212


def holdout_scenes():
    """The second held-out set (seed 2212, never used before), rendered after the finder was
    frozen again on 2026-11-25 (the shortest frame's ceiling codes taken as clipped): drawn as
    ``fresh`` is, with 2, 3, 4 or 5 frames."""
    return fresh_scenes(HOLDOUT_SEED, "holdout", [2, 3, 4, 5])


def fresh_scenes(seed=None, prefix="fresh", frame_counts=(2, 3, 3, 5)):
    """A held-out set rendered after the detector was frozen (seed 2211, never used before):
    6 scenes per elevation band (3–5, 5–10, 10–20, 20–45, 45–90°), azimuth, sky (clear, hazy,
    intermediate, overcast), a cloud over the sun, clouds elsewhere, trees or buildings, lens
    180°/190°, size, 2/3/5 frames and exposure all drawn from the seed. Every field is drawn in
    the same order for every scene, so adding scenes never changes the earlier ones."""
    seed = FRESH_SEED if seed is None else seed
    rng = random.Random(seed)
    scenes = []
    per_band = 6
    for b, (lo, hi) in enumerate(FRESH_BANDS):
        for k in range(per_band):
            i = b * per_band + k
            el = rng.uniform(lo, hi)
            az = rng.uniform(0, 360)
            kind = rng.choices(["clear", "hazy", "intermediate", "overcast"], [0.35, 0.3, 0.2, 0.15])[0]
            over_sun, elsewhere, obstacle = rng.random() < 0.2, rng.random() < 0.3, rng.random() < 0.35
            clouds, obstacles = [], []
            # Drawn whether used or not (the stream stays aligned).
            r, off, t, bright = rng.uniform(4, 9), rng.uniform(0, 1), rng.uniform(0, 360), rng.uniform(3, 12)
            if over_sun and kind != "overcast":
                off *= r - 2
                caz = az + off * math.sin(math.radians(t)) / max(math.cos(math.radians(el)), 0.2)
                cel = min(el + off * math.cos(math.radians(t)), 89.0)
                clouds.append(dict(az=caz, el=cel, radius=r, brightness=bright, rim=1.4))
            others = [
                dict(
                    az=rng.uniform(0, 360),
                    el=rng.uniform(8, 70),
                    radius=rng.uniform(3, 10),
                    brightness=rng.uniform(2, 8),
                    rim=rng.uniform(1.1, 1.6),
                )
                for _ in range(3)
            ]
            n_others = rng.randint(1, 3)
            if elsewhere:
                clouds += [
                    c
                    for c in others[:n_others]
                    if angle_between(vec(c["az"], c["el"]), vec(az, el)) > c["radius"] + 4
                ]
            okind = rng.choice(["trees", "buildings"])
            height, centre_off, width = rng.uniform(4, 14), rng.uniform(-180, 180), rng.uniform(40, 140)
            if obstacle:
                centre = az + centre_off
                obstacles.append(
                    dict(kind=okind, seed=seed + i, height=height,
                         **{"from": centre - width / 2, "to": centre + width / 2})
                )
            fov = rng.choice([180.0, 190.0])
            size = rng.choice([256, 320, 384])
            frames = rng.choice(list(frame_counts))
            ev = round(rng.uniform(-1.0, 1.5), 2)
            dn, dh = illuminance(kind, el)
            scenes.append(
                dict(
                    name=f"{prefix}{i:02d}",
                    set=prefix,
                    split="held-out",
                    sun_request=[az, el],
                    sky=kind,
                    direct_normal_lux=dn,
                    diffuse_horizontal_lux=dh,
                    clouds=clouds,
                    obstacles=obstacles,
                    fov_deg=fov,
                    size=size,
                    camera=dict(ev_offset=ev, evs=FRAME_SETS[frames], seed=seed * 10 + i),
                    time=None,
                    latitude_deg=None,
                    longitude_deg=None,
                )
            )
    return scenes


# The fresh scenes CI renders (256² or 320², every band, a cloud over the sun, trees), chosen by
# what they are, not by how the detector did on them.
CI_SCENES = ["fresh02", "fresh07", "fresh16", "fresh19", "fresh25", "fresh27"]


def day_scenes():
    lat, lon = 47.05, 8.31
    tz = dt.timezone(dt.timedelta(hours=2))
    scenes = []
    trees = dict(kind="trees", seed=7, height=9.0, **{"from": 250.0, "to": 320.0})
    for hour in range(6, 22):
        when = dt.datetime(2026, 6, 21, hour, 0, 0, tzinfo=tz)
        az, el = sun_position(when, lat, lon)
        if el < 2.5:
            continue
        kind = "clear" if hour not in (11, 12) else "hazy"
        clouds = []
        if hour in (9, 13, 17):
            clouds.append(dict(az=az + 2.0, el=min(el + 1.0, 89.0), radius=7.0, brightness=6.0, rim=1.4))
        if hour in (10, 15):
            clouds.append(dict(az=(az + 120) % 360, el=35.0, radius=8.0, brightness=5.0, rim=1.3))
        dn, dh = illuminance(kind, el)
        scenes.append(
            dict(
                name=f"day{hour:02d}",
                set="day",
                split="held-out",
                sun_request=[az, el],
                sky=kind,
                direct_normal_lux=dn,
                diffuse_horizontal_lux=dh,
                clouds=clouds,
                obstacles=[trees],
                fov_deg=190.0,
                size=320,
                camera=dict(ev_offset=0.0, evs=FRAME_SETS[3], seed=2000 + hour),
                time=when.isoformat(),
                latitude_deg=lat,
                longitude_deg=lon,
            )
        )
    return scenes


def issue_scenes():
    return [
        dict(
            name="issue22",
            set="issue",
            split="held-out",
            sun_request=[250.0, 10.0],
            sky="clear",
            direct_normal_lux=40000.0,
            diffuse_horizontal_lux=9000.0,
            clouds=[],
            obstacles=[],
            fov_deg=180.0,
            size=512,
            camera=dict(ev_offset=1.75, evs=FRAME_SETS[3], seed=22),
            time=None,
            latitude_deg=None,
            longitude_deg=None,
        )
    ]


def key_of(scene):
    """A hash of what shapes the render (not the camera, name or split)."""
    shape = {k: v for k, v in scene.items() if k not in ("camera", "name", "split", "set")}
    blob = json.dumps(dict(shape, version=VERSION, fine=FINE), sort_keys=True).encode()
    return hashlib.sha1(blob).hexdigest()[:12]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--set", choices=["sweep", "fresh", "holdout", "ci", "day", "issue", "all"], default="all")
    ap.add_argument("--split", choices=["tune", "held-out", "both"], default="both")
    ap.add_argument("--only", help="render only scenes whose name starts with this")
    ap.add_argument("--describe", action="store_true", help="print the scenes, render nothing")
    args = ap.parse_args()
    scenes = []
    if args.set in ("sweep", "all"):
        scenes += sweep_scenes()
    if args.set in ("fresh", "all"):
        scenes += fresh_scenes()
    if args.set in ("holdout", "all"):
        scenes += holdout_scenes()
    if args.set == "ci":
        scenes += [s for s in fresh_scenes() if s["name"] in CI_SCENES]
    if args.set in ("day", "all"):
        scenes += day_scenes()
    if args.set in ("issue", "all"):
        scenes += issue_scenes()
    if args.split != "both":
        scenes = [s for s in scenes if s["split"] == args.split]
    if args.only:
        scenes = [s for s in scenes if s["name"].startswith(args.only)]
    if args.describe:
        for s in scenes:
            hidden = "cloud-over-sun" if any(
                angle_between(vec(c["az"], c["el"]), vec(*s["sun_request"])) < c["radius"] for c in s["clouds"]
            ) else ""
            print(f"{s['name']} el {s['sun_request'][1]:5.1f} az {s['sun_request'][0]:5.1f} {s['sky']:12s} "
                  f"clouds {len(s['clouds'])} obstacles {len(s['obstacles'])} fov {s['fov_deg']:.0f} "
                  f"size {s['size']} frames {len(s['camera']['evs'])} ev {s['camera']['ev_offset']:+} {hidden}")
        return
    os.makedirs(args.out, exist_ok=True)
    written = []
    for s in scenes:
        folder = os.path.join(args.out, f"{s['name']}-{key_of(s)}")
        if os.path.exists(os.path.join(folder, "render.json")):
            print(f"{s['name']}: cached", file=sys.stderr)
        else:
            t0 = time.time()
            render(s, folder)
            print(f"{s['name']}: rendered in {time.time() - t0:.1f} s", file=sys.stderr)
        # The scene (camera and split included, which the render does not depend on) and what
        # the render found, rewritten on every run.
        with open(os.path.join(folder, "render.json")) as f:
            truth = dict(s, **json.load(f))
        write_json(os.path.join(folder, "truth.json"), truth)
        written.append(folder)
    for w in written:
        print(w)


if __name__ == "__main__":
    main()
