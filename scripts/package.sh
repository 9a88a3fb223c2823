#!/usr/bin/env bash
# Build the Debian package: target/debian/chromacal_VERSION-1_ARCH.deb.
#
#   scripts/package.sh              release build, then the package
#   scripts/package.sh --no-build   package the binary already at
#                                   ${CARGO_TARGET_DIR:-target}/release/chromacal
#                                   (the package test puts the one it tests there)
#   scripts/package.sh ... ARGS     ARGS go to cargo deb (-o DIR, --fast, ...)
#
# Needs cargo-deb (`cargo install --locked cargo-deb`). The manual pages and shell
# completions are made by the binary itself, so they match its command line.
set -euo pipefail
cd "$(dirname "$0")/.."
dir="${CARGO_TARGET_DIR:-target}/release"
if [ "${1:-}" = "--no-build" ]; then
    shift
else
    cargo build --locked --release
fi
binary="$dir/chromacal"
rm -rf "$dir/assets"
mkdir -p "$dir/assets/completions"
"$binary" man -o "$dir/assets/man" 2>/dev/null
gzip -9n -f "$dir"/assets/man/*.1
"$binary" completions bash >"$dir/assets/completions/chromacal.bash"
"$binary" completions zsh >"$dir/assets/completions/_chromacal"
"$binary" completions fish >"$dir/assets/completions/chromacal.fish"
exec cargo deb --locked --no-build "$@"
