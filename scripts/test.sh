#!/usr/bin/env bash
# Every test, on a fresh machine: installs what the tests drive from outside Rust
# (Debian's Chromium, for the web patch page in a real browser) when it is missing,
# then runs the suite. .ci/run calls this; the README's test command is this.
set -euo pipefail
cd "$(dirname "$0")/.."

have_browser() {
    command -v chromium >/dev/null || command -v chromium-headless-shell >/dev/null
}

if ! have_browser; then
    echo "scripts/test.sh: installing Chromium for the browser tests" >&2
    sudo=""
    if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq chromium >/dev/null
fi

cargo test --locked "$@"
