#!/usr/bin/env bash
# Every test, on a fresh machine: installs what the tests drive from outside Rust
# (Debian's Chromium, for the web patch page in a real browser) when it is missing,
# then runs the suite. .ci/run calls this; the README's test command is this.
#
#   scripts/test.sh                 the whole suite
#   scripts/test.sh --soak N        only the soaks: the daemon kill test with N
#                                   SIGKILLs (CHROMACAL_SOAK_SEED=S picks the kill
#                                   times), and the parser fuzz with 20 × N cases
#                                   per parser
#   scripts/test.sh --release       the whole suite built as `cargo run --release`
#                                   builds the program (optimised code is where a
#                                   compiler's faults show: see build.rs)
#   scripts/test.sh ARGS...         passed to `cargo test --workspace --locked
#                                   --features chromacal/peer-engines`
set -euo pipefail
cd "$(dirname "$0")/.."

if [ "${1:-}" = "--soak" ]; then
    kills="${2:?--soak needs a number of kills}"
    CHROMACAL_SOAK_KILLS="$kills" cargo test --locked --features chromacal/peer-engines --test daemon_kill -- --nocapture
    CHROMACAL_FUZZ_CASES="$((kills * 20))" exec cargo test --locked --features chromacal/peer-engines --test parser_fuzz -- --nocapture
fi

updated=""
need_package() {
    echo "scripts/test.sh: installing $1 for the tests" >&2
    sudo=""
    if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
    if [ -z "$updated" ]; then
        $sudo apt-get update -qq
        updated=yes
    fi
    # shellcheck disable=SC2086 # $1 may name several packages
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq $1 >/dev/null
}

have_browser() {
    command -v chromium >/dev/null || command -v chromium-headless-shell >/dev/null
}

# The web patch page is tested in a real browser.
have_browser || need_package chromium
# The systemd units are checked by systemd-analyze; the API's refusals by curl.
command -v systemd-analyze >/dev/null || need_package systemd
# The XDG autostart entry is checked by the freedesktop validator.
command -v desktop-file-validate >/dev/null || need_package desktop-file-utils
command -v curl >/dev/null || need_package curl
# GNU time: a test reads peak memory with it.
[ -x /usr/bin/time ] || need_package time
# Exports are read back by independent readers: ArgyllCMS, Little CMS's transicc,
# and PsychoPy's loader (json_tricks with numpy, in Debian's Python).
command -v iccdump >/dev/null || need_package argyll
command -v transicc >/dev/null || need_package liblcms2-utils
# 3D LUTs are applied by ffmpeg's lut3d filter.
command -v ffmpeg >/dev/null || need_package ffmpeg
/usr/bin/python3 -c "import json_tricks, numpy" 2>/dev/null ||
    need_package "python3-json-tricks python3-numpy"
# The patch window, the video LUT and the emulator that looks at the screen are
# tested against a real X server: Xorg with the dummy driver (Xvfb's CRTC gamma ramp
# does not read back what was set), with xrandr to change it from outside and
# ArgyllCMS's dispwin to read the LUT back; EDID parsing against edid-decode.
[ -x /usr/lib/xorg/Xorg ] || command -v Xorg >/dev/null || need_package xserver-xorg-core
[ -e /usr/lib/xorg/modules/drivers/dummy_drv.so ] || need_package xserver-xorg-video-dummy
command -v xrandr >/dev/null || need_package x11-xserver-utils
command -v edid-decode >/dev/null || need_package edid-decode
# The Wayland patch surface, outputs, gamma control and screencopy are tested against
# a real compositor: sway on its headless backend (run as an unprivileged user), with
# grim reading the screen back; setpriv (util-linux) drops to that user.
command -v sway >/dev/null || need_package sway
command -v grim >/dev/null || need_package grim
command -v setpriv >/dev/null || need_package util-linux
# Registration with colord is tested against a real colord on a private system bus.
[ -x /usr/libexec/colord ] || need_package colord
command -v dbus-daemon >/dev/null || need_package dbus-daemon
command -v gdbus >/dev/null || need_package libglib2.0-bin
# The fleet's metrics and events are tested against a real Prometheus (with promtool
# for the shipped rules) and a real Mosquitto broker, read by its own client.
command -v mosquitto >/dev/null || [ -x /usr/sbin/mosquitto ] || need_package mosquitto
command -v mosquitto_sub >/dev/null || need_package mosquitto-clients
command -v prometheus >/dev/null || need_package prometheus
command -v promtool >/dev/null || need_package prometheus
# The Debian package is built by cargo-deb and installed by dpkg into a scratch root.
cargo deb --version >/dev/null 2>&1 || {
    echo "scripts/test.sh: installing cargo-deb for the package test" >&2
    # Not fatal: without it only the package test fails, and says why.
    cargo install --locked --quiet cargo-deb ||
        echo "scripts/test.sh: cargo-deb could not be installed; tests/package.rs will fail" >&2
}

# Building the suite takes about 4 GB under target/ (a clean checkout); say so up front
# rather than let the linker fail half an hour in with "No space left on device".
target_dir="${CARGO_TARGET_DIR:-target}"
mkdir -p "$target_dir"
free_kb="$(df --output=avail -k "$target_dir" 2>/dev/null | tail -1 | tr -d ' ' || true)"
if [ "$free_kb" -eq "$free_kb" ] 2>/dev/null && [ "$free_kb" -lt 4500000 ]; then
    echo "scripts/test.sh: warning: $((free_kb / 1024)) MB free where $target_dir is; building the suite from clean takes about 4 GB" >&2
fi

# Every crate of the workspace, built with the peer engines for `bench render`'s own
# test.
cargo test --workspace --locked --features chromacal/peer-engines "$@"
