#!/usr/bin/env bash
# The end-to-end speed benchmark of issue #11. From the repository root:
#
#   scripts/bench.sh            # ≥ 5 alternating runs on 3 × 2448² JPEGs, then the scaling table
#   scripts/bench.sh --quick    # the same, with a smaller scaling table (up to 24 MP)
#   scripts/bench.sh --runs 9 --no-scaling
#   scripts/bench.sh --batch    # only the station benchmark (issue #21), see below
#   scripts/bench.sh --noise    # only the noise-model merge against the hat (issue #27), see below
#
# (1) `skydome merge A B C -o s.hdr --preview s.jpg` (calibration from the frames, preview on),
# (2) the decode floor: the same three JPEGs decoded by libjpeg-turbo through Pillow, one thread,
# (3) OpenCV's equivalent pipeline in Python (scripts/bench_helper.py opencv),
# run alternately, each a whole process timed by /usr/bin/time (wall clock and peak resident
# memory). Prints medians, skydome/floor and OpenCV/skydome, and each one's peak memory; then
# the whole fish-eye dome (lens, crop, sun, preview) on 3 × 12 MP; then `skydome merge` (no
# preview) at 3, 5 and 9 frames × 6, 12, 24 and 50 MP.
#
# --batch: a synthetic station day (`skydome synth --captures`, EXIF times, one folder) of
# $SKYDOME_BENCH_CAPTURES (default 8) captures of 3 × 6 MP and of 3 × 12 MP frames through
# `skydome batch --fisheye --crop` with --jobs 1 and --jobs 2: captures per minute and peak memory;
# the batch's overhead against the same captures as N separate `skydome merge` processes (same
# options, one after the other, against --jobs 1: ≤ 10 % is the target); and "a year of 1-minute
# captures" (525,600) in hours on this machine and on 10 and 100 such Slurm nodes, from the
# measured cost per capture (ideal scaling: shards share nothing but the output folder).
#
# --noise: `skydome merge --weighting noise` against `--weighting hat` (the default), the same
# bracket and options otherwise, alternating, $RUNS runs each, on 3, 5 and 9 frames (2 EV apart) of 6 MP and 12 MP synthetic
# brackets: median wall and CPU time of each whole process, their ratio, and the difference — the
# noise merge's own cost (its noise-model fit and its refinement of the hat's estimate), since
# everything else (decoding, calibration, writing) is the same work. The merge stage alone, with
# nothing else in the process: `cargo bench -p skydome --bench calibrate_merge -- merge_6mp/noise`
# against `merge_6mp/lut_into`.
#
# Needs python3 with venv, and /usr/bin/time (Debian: apt-get install time). The Python packages
# (numpy, opencv-python-headless, Pillow) go into a virtual environment, $SKYDOME_BENCH_VENV or
# target/bench-venv. Scratch files go to $SKYDOME_BENCH_DIR or target/bench. The machine should be
# otherwise idle: other processes inflate every figure.
set -euo pipefail
cd "$(dirname "$0")/.."

RUNS=5
QUICK=0
SCALING=1
BATCH=0
NOISE=0
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) QUICK=1 ;;
    --runs) RUNS="$2"; shift ;;
    --no-scaling) SCALING=0 ;;
    --batch) BATCH=1 ;;
    --noise) NOISE=1 ;;
    -h|--help) sed -n '2,37p' "$0"; exit 0 ;;
    *) echo "bench.sh: unknown option $1 (use --quick, --runs N, --no-scaling, --batch, --noise)" >&2; exit 2 ;;
  esac
  shift
done
if [ "$RUNS" -lt 5 ]; then echo "bench.sh: use at least 5 runs" >&2; exit 2; fi
[ -x /usr/bin/time ] || { echo "bench.sh: /usr/bin/time is missing (apt-get install time)" >&2; exit 1; }

WORK="${SKYDOME_BENCH_DIR:-$PWD/target/bench}"
VENV="${SKYDOME_BENCH_VENV:-$PWD/target/bench-venv}"
mkdir -p "$WORK"

echo "building skydome (release)…" >&2
cargo build --release -q -p skydome-cli
SKYDOME="$PWD/target/release/skydome"

# --noise compares skydome with itself: no Python packages.
if [ "$NOISE" = 0 ]; then
  if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV"
  fi
  "$VENV/bin/pip" install --quiet --disable-pip-version-check numpy opencv-python-headless Pillow
fi
PY="$VENV/bin/python"
HELPER="$PWD/scripts/bench_helper.py"

# synth SIZE EVS DIR: a synthetic fish-eye bracket (JPEG frames, times.txt), made once.
synth() {
  local size="$1" evs="$2" dir="$3"
  if [ ! -f "$dir/times.txt" ]; then
    mkdir -p "$dir"
    "$SKYDOME" synth -o "$dir" --size "$size" --evs="$evs" --seed 1 --quiet --force
  fi
}
frames_of() { awk -v d="$1" '!/^#/ && NF {printf "%s/%s ", d, $1}' "$1/times.txt"; }
times_of() { awk '!/^#/ && NF {printf "%s%s", (n++?",":""), $2}' "$1/times.txt"; }

# timed NAME CMD...: runs CMD once under /usr/bin/time, appends "wall_s peak_kB user_s sys_s" to
# $WORK/NAME.txt.
timed() {
  local name="$1"; shift
  /usr/bin/time -f "%e %M %U %S" -o "$WORK/.time" "$@" >/dev/null 2>"$WORK/.stderr" || {
    echo "bench.sh: $name failed:" >&2; cat "$WORK/.stderr" >&2; exit 1; }
  cat "$WORK/.time" >> "$WORK/$name.txt"
}

# --- --noise: the noise-model merge against the hat (issue #27) ----------------------------------
if [ "$NOISE" = 1 ]; then
  rm -f "$WORK"/noise_*.txt
  for size in 2448 3464; do
    for nf in 3 5 9; do
      case "$nf" in
        3) evs="-2,0,2" ;;
        5) evs="-4,-2,0,2,4" ;;
        9) evs="-8,-6,-4,-2,0,2,4,6,8" ;;
      esac
      if [ "$nf" = 3 ]; then d="$WORK/bracket_${size}_3"; else d="$WORK/bracket_${size}_${nf}x2ev"; fi
      synth "$size" "$evs" "$d"
      echo "$nf × ${size}²: $RUNS alternating runs of --weighting hat and --weighting noise…" >&2
      for i in $(seq "$RUNS"); do
        for wt in hat noise; do
          # shellcheck disable=SC2046
          timed "noise_${size}_${nf}_$wt" "$SKYDOME" merge $(frames_of "$d") --times "$(times_of "$d")" \
            --weighting "$wt" -o "$WORK/n.hdr" --force --quiet
        done
      done
    done
  done
  python3 - "$WORK" <<'PY'
import statistics, sys
w = sys.argv[1]
def med(name, col):
    rows = [list(map(float, l.split())) for l in open(f"{w}/{name}.txt") if l.strip()]
    if col == "cpu":
        return statistics.median(r[2] + r[3] for r in rows), len(rows)
    return statistics.median(r[0] for r in rows), len(rows)
print(f"{'skydome merge':24} {'':5} {'hat':>9} {'noise':>9} {'noise/hat':>10} {'noise−hat':>10}")
for size, mp in [(2448, "6 MP"), (3464, "12 MP")]:
    for nf in (3, 5, 9):
        for col in ("wall", "cpu"):
            (h, n), (s, _) = med(f"noise_{size}_{nf}_hat", col), med(f"noise_{size}_{nf}_noise", col)
            print(f"{f'{nf} × ' + mp:24} {col:5} {h:8.3f}s {s:8.3f}s {s / h:10.3f} {1000 * (s - h):8.0f}ms")
print(f"medians of {n} alternating runs each, whole processes (CPU = user + system, all threads)")
PY
  exit 0
fi

# --- --batch: the station benchmark (issue #21) ----------------------------------------------
if [ "$BATCH" = 1 ]; then
  N="${SKYDOME_BENCH_CAPTURES:-8}"
  DOME=(--fisheye --lens-model equidistant --fov 235 --crop)
  rm -f "$WORK"/batch_*.txt
  for size in 2448 3464; do
    D="$WORK/station_${size}_$N"
    if [ ! -f "$D/IMG_$(printf %04d $((3 * N - 1))).jpg" ]; then
      rm -rf "$D"; mkdir -p "$D"
      echo "synthetic day: $N captures of 3 × ${size}²…" >&2
      "$SKYDOME" synth -o "$D" --captures "$N" --interval 60 --size "$size" --quiet
    fi
    for j in 1 2; do
      rm -rf "$WORK/batch_out"; mkdir -p "$WORK/batch_out"
      echo "skydome batch -j $j on 3 × ${size}²…" >&2
      timed "batch_${size}_j$j" "$SKYDOME" batch "$D" -o "$WORK/batch_out" "${DOME[@]}" -j "$j" --quiet
    done
    echo "$N separate skydome merge on 3 × ${size}²…" >&2
    start=$(date +%s.%N)
    for c in $(seq 0 $((N - 1))); do
      fr=""
      for f in 0 1 2; do fr="$fr $D/IMG_$(printf %04d $((3 * c + f))).jpg"; done
      timed "batch_${size}_single" "$SKYDOME" merge $fr -o "$WORK/single.hdr" "${DOME[@]}" --force --quiet
    done
    end=$(date +%s.%N)
    echo "$start $end" > "$WORK/batch_${size}_singles_wall.txt"
  done
  python3 - "$WORK" "$N" <<'PY'
import sys
work, n = sys.argv[1], int(sys.argv[2])
def rows(name):
    return [list(map(float, l.split())) for l in open(f"{work}/{name}.txt")]
print(f"\nskydome batch on a synthetic station day, {n} captures of 3 frames, this machine")
print(f"{'frames':14} {'jobs':>4} {'wall':>9} {'captures/min':>13} {'peak MB':>8}")
best = {}
for size, mp in [(2448, "3 × 6 MP"), (3464, "3 × 12 MP")]:
    for j in (1, 2):
        wall, peak, _, _ = rows(f"batch_{size}_j{j}")[0]
        print(f"{mp:14} {j:>4} {wall:8.2f}s {60 * n / wall:13.1f} {peak / 1024:8.0f}")
        best[size] = min(best.get(size, 1e9), wall / n)
    singles = rows(f"batch_{size}_single")
    total = sum(r[0] for r in singles)
    b1 = rows(f"batch_{size}_j1")[0][0]
    print(f"{mp:14}  {n} separate merges {total:7.2f}s (peak {max(r[1] for r in singles) / 1024:.0f} MB); "
          f"batch -j 1 / separate = {b1 / total:.3f} (overhead {100 * (b1 / total - 1):+.1f} %)")
print("\na year of 1-minute captures (525,600), from the best measured cost per capture:")
print(f"{'frames':14} {'s/capture':>10} {'1 machine':>12} {'10 nodes':>10} {'100 nodes':>10}")
for size, mp in [(2448, "3 × 6 MP"), (3464, "3 × 12 MP")]:
    c = best[size]
    h = 525600 * c / 3600
    print(f"{mp:14} {c:10.3f} {h:10.1f} h {h / 10:8.1f} h {h / 100:8.2f} h")
PY
  exit 0
fi

# --- The head-to-head on 3 × 2448² ------------------------------------------------------------
B="$WORK/bracket_2448_3"
synth 2448 "-2,0,2" "$B"
FRAMES=$(frames_of "$B")
TIMES=$(times_of "$B")
rm -f "$WORK"/skydome.txt "$WORK"/floor.txt "$WORK"/opencv.txt
echo "3 × 2448² JPEG frames, $RUNS alternating runs of each…" >&2
for i in $(seq "$RUNS"); do
  # shellcheck disable=SC2086
  timed skydome "$SKYDOME" merge $FRAMES --times "$TIMES" -o "$WORK/s.hdr" --preview "$WORK/s.jpg" --force --quiet
  # shellcheck disable=SC2086
  timed floor "$PY" "$HELPER" decode $FRAMES
  # shellcheck disable=SC2086
  timed opencv "$PY" "$HELPER" opencv "$WORK" "$TIMES" $FRAMES
done

"$PY" - "$WORK" <<'EOF'
import statistics, sys, os
w = sys.argv[1]
def load(n):
    rows = [l.split() for l in open(os.path.join(w, n + ".txt")) if l.strip()]
    wall = statistics.median(float(r[0]) for r in rows)
    cpu = statistics.median(float(r[2]) + float(r[3]) for r in rows)
    return wall, max(int(r[1]) for r in rows) / 1024, cpu, len(rows)
s, f, o = load("skydome"), load("floor"), load("opencv")
print(f"{'3 × 2448² (6 MP) JPEGs':46} {'median wall':>12} {'median CPU':>11} {'peak memory':>12}")
for name, v in [("skydome merge --preview (calibrating)", s),
                ("decode floor (Pillow/libjpeg-turbo, 1 thread)", f),
                ("OpenCV (Debevec calibrate+merge, Reinhard)", o)]:
    print(f"{name:46} {v[0]:10.3f} s {v[2]:9.3f} s {v[1]:9.0f} MB")
print(f"runs: {s[3]} each, alternating; CPU = user + system time of the process (all threads)")
print(f"skydome / decode floor = {s[0] / f[0]:.2f} wall, {s[2] / f[2]:.2f} CPU   (target ≤ 1.5)")
print(f"OpenCV / skydome       = {o[0] / s[0]:.1f} wall, {o[2] / s[2]:.1f} CPU    (target ≥ 10)")
EOF

# --- The whole fish-eye dome (what the phone app does) on 3 × 3464² (12 MP) ---------------------
# Lens circle, calibration, merge, crop to the 180° dome, sun detection and disc, preview.
F="$WORK/fisheye_3464_3"
synth 3464 "-2,0,2" "$F"
rm -f "$WORK/fisheye.txt"
echo "3 × 3464² fish-eye frames, $RUNS runs of the whole dome…" >&2
for i in $(seq "$RUNS"); do
  # shellcheck disable=SC2046
  timed fisheye "$SKYDOME" merge $(frames_of "$F") --times "$(times_of "$F")" --fisheye \
    --lens-model stereographic --fov 235 --crop --north 0 --sun auto \
    -o "$WORK/f.hdr" --preview "$WORK/f.jpg" --force --quiet
done
"$PY" - "$WORK" <<'EOF'
import statistics, sys, os
rows = [l.split() for l in open(os.path.join(sys.argv[1], "fisheye.txt")) if l.strip()]
wall = statistics.median(float(r[0]) for r in rows)
cpu = statistics.median(float(r[2]) + float(r[3]) for r in rows)
peak = max(int(r[1]) for r in rows) / 1024
print()
print(f"{'3 × 3464² (12 MP) fish-eye dome':46} {'median wall':>12} {'median CPU':>11} {'peak memory':>12}")
print(f"{'skydome merge --fisheye --crop --sun auto --preview':46} {wall:10.3f} s {cpu:9.3f} s {peak:9.0f} MB")
EOF

# --- Scaling: frames × megapixels ---------------------------------------------------------------
[ "$SCALING" = 1 ] || exit 0
if [ "$QUICK" = 1 ]; then SIZES="2448 3464 4899"; else SIZES="2448 3464 4899 7071"; fi
echo >&2
echo "scaling: skydome merge (calibrating, no preview), one run per cell…" >&2
printf "%-10s %-8s %10s %12s %14s\n" "size" "frames" "wall" "peak memory" "ns/(px·frame)"
for size in $SIZES; do
  for n in 3 5 9; do
    case "$n" in 3) evs="-2,0,2" ;; 5) evs="-2,-1,0,1,2" ;; 9) evs="-4,-3,-2,-1,0,1,2,3,4" ;; esac
    if [ "$QUICK" = 1 ] && [ "$size" = 4899 ] && [ "$n" != 3 ]; then continue; fi
    d="$WORK/bracket_${size}_$n"
    synth "$size" "$evs" "$d"
    rm -f "$WORK/scale.txt"
    # shellcheck disable=SC2046
    timed scale "$SKYDOME" merge $(frames_of "$d") --times "$(times_of "$d")" -o "$WORK/scale.hdr" --force --quiet
    read -r wall kb _ < "$WORK/scale.txt"
    mp=$(awk -v s="$size" 'BEGIN{printf "%.0f", s*s/1e6}')
    awk -v s="$size" -v n="$n" -v w="$wall" -v k="$kb" -v mp="$mp" \
      'BEGIN{printf "%-10s %-8s %8.2f s %9.0f MB %14.1f\n", s "² (" mp " MP)", n, w, k/1024, w*1e9/(s*s*n)}'
    # 50 MP brackets are ~0.5–1.3 GB of JPEG; keep only the 6 MP ones between runs.
    if [ "$size" != 2448 ]; then rm -rf "$d"; fi
  done
done
