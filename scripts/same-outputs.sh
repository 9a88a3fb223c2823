#!/usr/bin/env bash
# What the program writes for fixed inputs and seeds, from two builds, compared byte for
# byte: a change meant to leave behaviour alone (a move, a split into crates, a
# refactor) shows here if it did not. The clock is frozen (libfaketime, Debian's
# `faketime`) so that time stamps and run ids come out the same; log lines on stderr
# are compared without their targets (a module's path is not behaviour).
#
#   scripts/same-outputs.sh REV               build commit REV and the working tree
#                                             (release), run both, compare
#   scripts/same-outputs.sh --bin OLD NEW     compare two chromacal binaries
#   options (first):  --keep DIR              leave both sets of outputs in DIR
#                     --no-bench              leave out `bench --quick` (minutes)
#
# What runs: the default `calibrate` (text, --json and its report), `fit`, `check
# --json`, `profile show` and `report` on every `.ti3` of ../shared/data/measurements and
# fixtures/, every `export` format with and without a calibration target, `render` of
# the ColorChecker (CSV, PNG, --explain) and of an XYZ image, `lut3d` in both formats,
# with SGCK and through the calibration, `spectrum`, and the tables of `bench --quick`
# with every timing column blanked. Exit 0 when every output is the same, 1 when some
# differ (the differing files are listed), 2 on a usage or build error.
set -euo pipefail
cd "$(dirname "$0")/.."
root="$(pwd)"

keep="" bench=yes
while [ $# -gt 0 ]; do
    case "$1" in
        --keep) keep="$2"; shift 2 ;;
        --no-bench) bench=""; shift ;;
        *) break ;;
    esac
done

command -v faketime >/dev/null || {
    echo "same-outputs: needs faketime (apt-get install faketime)" >&2
    exit 2
}
work="${keep:-$(mktemp -d /tmp/chromacal-same-outputs.XXXXXX)}"
mkdir -p "$work"
[ -n "$keep" ] || trap 'rm -rf "$work"' EXIT

if [ "${1:-}" = "--bin" ]; then
    [ $# -eq 3 ] || { echo "usage: $0 --bin OLD NEW" >&2; exit 2; }
    old_bin="$(realpath "$2")"
    new_bin="$(realpath "$3")"
elif [ $# -eq 1 ]; then
    rev="$1"
    git worktree add --detach "$work/old-tree" "$rev" >/dev/null
    trap 'git worktree remove --force "$work/old-tree" >/dev/null 2>&1 || true; [ -n "$keep" ] || rm -rf "$work"' EXIT
    (cd "$work/old-tree" && cargo build --release --locked --quiet) || exit 2
    cargo build --release --locked --quiet || exit 2
    old_bin="$work/old-tree/target/release/chromacal"
    new_bin="$root/target/release/chromacal"
else
    sed -n '2,20p' "$0" >&2
    exit 2
fi

data="$root/../shared/data"
checker="$data/colorchecker/colorchecker_n_ohta_5nm.csv"

# One command: its stdout, its stderr without log targets, and its exit code.
run() {
    local name="$1"
    shift
    set +e
    "$@" >"$name.out" 2>"$name.err.raw"
    echo $? >"$name.rc"
    set -e
    sed -E 's/ chromacal[a-z_]*(::[a-z0-9_]+)*: / /' "$name.err.raw" >"$name.err"
    rm -f "$name.err.raw"
}

# Every output of one binary, in $work/run (the same path for both binaries, since
# profiles record where their readings are), then moved to $work/$2.
outputs() {
    local bin="$1" into="$2"
    rm -rf "$work/run"
    mkdir -p "$work/run/home"
    (
        cd "$work/run"
        export HOME="$work/run/home" TZ=UTC LC_ALL=C NO_COLOR=1 FAKETIME_DONT_FAKE_MONOTONIC=1
        unset CHROMACAL_LOG RUST_LOG XDG_STATE_HOME STATE_DIRECTORY DISPLAY FAKETIME
        c() { faketime -f "2026-01-02 03:04:05" "$bin" "$@"; }

        run calibrate c calibrate --state-dir st --report calibrate.html
        run calibrate-json c calibrate --state-dir st-json --json
        run profile-show c profile show st/current.toml
        run report c report st/current.toml -o report.html

        n=0
        for m in "$data"/measurements/*.ti3 "$root"/fixtures/ti3/*.ti3 "$root"/fixtures/journals/*.jsonl; do
            n=$((n + 1))
            cp "$m" "set$n.${m##*.}"
            run "fit$n" c fit "set$n.${m##*.}" -o "fit$n.toml" --report "fit$n.html"
            run "check$n" c check "fit$n.toml" "set$n.${m##*.}" --json
            run "show$n" c profile show "fit$n.toml"
        done

        for f in icc4 icc2 ti3 psychopy json toml; do
            run "export-$f" c export st/current.toml --format "$f" -o "export.$f"
        done
        for f in icc4 icc2 cal; do
            run "export-target-$f" c export st/current.toml --format "$f" -o "export-target.$f" \
                --white D65 --tone gamma:2.2 --luminance 80
        done
        run export-fit-icc2 c export fit1.toml --format icc2 -o export-fit1.icc2

        run render-csv c render st/current.toml --reflectance "$checker" --illuminant D65 \
            --white-luminance 90 -o checker.csv
        run render-explain c render st/current.toml --reflectance "$checker" --illuminant D65 \
            --white-luminance 90 --grid 6x4 --at 0.25,0.25,0.5,0.5 --gamut grey-lab \
            --explain -o checker.png
        # A 64 × 48 XYZ image (PFM, bottom row first) sweeping the gamut and beyond it.
        python3 - <<'PY'
import struct
w, h = 64, 48
with open("scene.pfm", "wb") as f:
    f.write(b"PF\n%d %d\n-1.0\n" % (w, h))
    for j in range(h):
        for i in range(w):
            x, y = i / (w - 1), j / (h - 1)
            f.write(struct.pack("<3f", 120 * x * (1 - y), 110 * y, 130 * (1 - x) * y + 5))
PY
        run render-image c render st/current.toml --image scene.pfm -o scene.png
        run render-image-rounded c render st/current.toml --image scene.pfm --codes rounded \
            --gamut perpendicular-lab -o scene-rounded.csv

        run lut3d-cube c lut3d st/current.toml --source srgb --size 17 -o lut.cube
        run lut3d-3dl c lut3d st/current.toml --source bt1886 -o lut.3dl
        run lut3d-sgck c lut3d st/current.toml --source rec2020 --size 17 --gamut sgck -o sgck.cube
        run export-curves c export st/current.toml --format toml -o with-curves.toml \
            --white D65 --tone gamma:2.2 --luminance 80
        run lut3d-through c lut3d with-curves.toml --source srgb --size 9 --through-calibration -o through.cube

        run spectrum-reflectance c spectrum "$checker" --reflectance --illuminant D65 --json
        run spectrum-emission c spectrum "$data/illuminants/cie_A_5nm.csv" --emission

        if [ -n "$bench" ]; then
            # Timing columns blanked: any number followed by a unit of time or a rate.
            run bench c bench --quick --data "$data"
            # Its tables without what the machine's speed decides: every cell of a
            # column that holds a time or a rate, and any figure with a unit of time.
            python3 - bench.out <<'PY'
import re, sys
TIMING = re.compile(r"(^n=\d+$|time|µs|\bns\b|ns/|\bms\b|ms/|/s$|/ s|Mpixel|seconds|events|÷|instrument s)")
UNIT = re.compile(r"[0-9][0-9.,]*( ?)(ns|µs|ms|s|min)\b")
out, ends, timing = [], None, []
for line in open(sys.argv[1]).read().split("\n"):
    tokens = [(m.start(), m.end(), m.group()) for m in re.finditer(r"\S+(?: \S+)*", line)]
    if line.startswith("  ") and len(tokens) >= 3 and not re.search(r"[0-9]", tokens[0][2]) \
            and all(not re.fullmatch(r"[-0-9.,/ #]+", t[2]) for t in tokens[1:]):
        ends = [t[1] for t in tokens]
        timing = [bool(TIMING.search(t[2])) for t in tokens]
        out.append(" | ".join(t[2] for t in tokens))
        continue
    if ends and line.startswith("  ") and line.strip():
        # The first column is left-aligned, the others end where their headers end.
        first = re.split(r"\s{2,}", line[:ends[1]].strip())
        cells = ["  ".join(first[:-1]), first[-1]]
        for k in range(2, len(ends)):
            cells.append((line[ends[k - 1]:ends[k]] if k < len(ends) - 1 else line[ends[k - 1]:]).strip())
        cells = ["#" if timing[k] and cells[k] else cells[k] for k in range(len(cells))]
        out.append(UNIT.sub(r"#\1\2", " | ".join(cells)))
        continue
    ends = None
    out.append(UNIT.sub(r"#\1\2", line))
open(sys.argv[1], "w").write("\n".join(out))
PY
        fi
        rm -f st/lock st-json/lock
        # What a run measured of its own speed is not behaviour: the fit's time, as the
        # profiles, the summaries and the reports give it.
        grep -rlIE 'fit_s|fit time|render time' . | xargs -r sed -E -i \
            -e 's/(fit_s"?:? =? ?)[0-9.e+-]+/\1#/g' \
            -e 's/(fit time(<\/th><td[^>]*>| )?)[0-9.]+ ?(ns|µs|ms|s|min)/\1#/g' \
            -e 's/render time: [0-9.]+ ms with the full model, [0-9.]+ ms/render time: # with the full model, #/'
    )
    rm -rf "${work:?}/$into"
    mv "$work/run" "$work/$into"
}

echo "same-outputs: running $old_bin" >&2
outputs "$old_bin" old
echo "same-outputs: running $new_bin" >&2
outputs "$new_bin" new

if diff -r -q "$work/old" "$work/new" >"$work/differences"; then
    echo "same-outputs: every output the same ($(find "$work/new" -type f | wc -l) files)"
    exit 0
fi
echo "same-outputs: outputs differ:" >&2
cat "$work/differences" >&2
exit 1
