#!/usr/bin/env bash
# Fetches the real RAW bracket of the RAW tests (docs/accuracy.md "RAW brackets"): three DNGs
# of one scene from a Nikon D5000 at 1/640, 1/160 and 1/40 s (Adobe-converted, lossless JPEG
# tiles), the test images of HDRMerge (GPL-3.0-or-later, Debian's copyright file says so for
# every file of the source but the icons), taken from Debian's source package `hdrmerge`
# (0.5+git20200117) through apt. They are 33 MB, too large for the repository, so they are
# kept in a cache folder: $1, default target/raw-bracket-hdrmerge. The tests read them from
# there (SKYDOME_RAW_BRACKET_DIR names another folder) and skip with a message when missing.
#
# apt runs with its own source list and state under a temporary folder (deb-src twins of the
# machine's Debian entries), so the machine's apt configuration is not touched.
set -euo pipefail
cd "$(dirname "$0")/.."
DEST="${1:-target/raw-bracket-hdrmerge}"

# The files as shipped in hdrmerge_0.5+git20200117.orig.tar.gz, test/.
declare -A SHA=(
  [sample1.dng]=bf23aff5d67f0e0e40c009af82de35e9ad355e03d37ac1f400914729ac913250
  [sample2.dng]=d7cce08c59303b20a8486e39b27a15ddc7a1c1d6e1686bba7897c1831b330a94
  [sample3.dng]=6457be30d7ae8cd67fbe7ea35a8e8e0b4da1b27ebee944b517ba88e158fd8abd
  [LICENSE]=8ceb4b9ee5adedde47b31e975c1d90c73ad27b6b165a1dcd80c7c545eb65b903
)
ORIG_SHA=18f1db24c191936816fb09c3df864ade10958106c3bb2ff735a72e0b772da442

all_present() {
  for f in "${!SHA[@]}"; do
    [ -f "$DEST/$f" ] || return 1
    echo "${SHA[$f]}  $DEST/$f" | sha256sum --check --status || return 1
  done
}
if all_present; then
  echo "raw bracket: $DEST is complete"
  exit 0
fi

TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT
mkdir -p "$TMP/parts" "$TMP/lists/partial" "$TMP/cache/archives/partial" "$TMP/src"
: >"$TMP/sources.list"
if [ -f /etc/apt/sources.list ]; then
  sed -n 's/^deb \(.*debian.*\)$/deb-src \1/p' /etc/apt/sources.list >>"$TMP/sources.list"
fi
for f in /etc/apt/sources.list.d/*.sources; do
  [ -f "$f" ] || continue
  grep -qi debian "$f" || continue
  sed 's/^Types: deb$/Types: deb-src/' "$f" >"$TMP/parts/$(basename "$f")"
done
APT=(-o Dir::Etc::SourceList="$TMP/sources.list" -o Dir::Etc::SourceParts="$TMP/parts"
  -o Dir::State::Lists="$TMP/lists" -o Dir::Cache="$TMP/cache" -o APT::Sandbox::User=root
  -o Debug::NoLocking=1)
apt-get "${APT[@]}" -qq update
# Only the upstream tarball is needed (Debian's packaging part may be missing on a mirror, which
# apt reports as an error after it has fetched the tarball): its messages are shown on failure.
(cd "$TMP/src" && apt-get "${APT[@]}" -qq source --download-only hdrmerge=0.5+git20200117-2) \
  >"$TMP/apt.log" 2>&1 || true
ORIG="$TMP/src/hdrmerge_0.5+git20200117.orig.tar.gz"
if [ ! -f "$ORIG" ]; then
  cat "$TMP/apt.log" >&2
  echo "raw bracket: hdrmerge's source tarball could not be fetched" >&2
  exit 1
fi
echo "$ORIG_SHA  $ORIG" | sha256sum --check --status ||
  { echo "raw bracket: hdrmerge's source tarball has another checksum" >&2; exit 1; }
tar -xzf "$ORIG" -C "$TMP/src" hdrmerge-master/LICENSE hdrmerge-master/test/sample1.dng \
  hdrmerge-master/test/sample2.dng hdrmerge-master/test/sample3.dng
mkdir -p "$DEST"
cp "$TMP"/src/hdrmerge-master/test/sample?.dng "$TMP/src/hdrmerge-master/LICENSE" "$DEST/"
cat >"$DEST/SOURCE.txt" <<'EOF'
HDRMerge's test images test/sample1.dng, sample2.dng, sample3.dng and its LICENSE (GPL-3.0-or-later),
from Debian's source package hdrmerge 0.5+git20200117 (hdrmerge_0.5+git20200117.orig.tar.gz, upstream
jcelaya/hdrmerge). Debian's copyright file: "Files: * Copyright: 2012-2020 Javier Celaya, contributors;
License: GPL-3+". Nikon D5000, 24 mm, f/6.3, ISO 200, 2014-03-09 13:25:51, hand-held aperture-priority
bracket: sample2 1/640 s (EV 0), sample1 1/160 s (+2), sample3 1/40 s (+4). DNG 1.3 from the Adobe DNG
Converter (original names DSC_5827-5829.NEF): lossless JPEG tiles of two components, 4310 x 2868, GBRG,
white level 3840. Fetched by scripts/fetch-raw-bracket.sh; not redistributed by skydome.
EOF
all_present || { echo "raw bracket: checksums differ after the fetch" >&2; exit 1; }
echo "raw bracket: fetched into $DEST"
