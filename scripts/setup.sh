#!/usr/bin/env bash
# The Debian packages robotid needs beyond the stock Rust toolchain:
# OpenBLAS and LAPACK for clarabel's semidefinite cones (the physically
# consistent estimate), Chromium to render the HTML report in a test, and
# strace, with which a test counts what identify reads.
# Installs only what is missing; needs root or sudo when something is.
set -euo pipefail
packages=(libopenblas-dev libgfortran-12-dev chromium fonts-dejavu-core strace)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing ${missing[*]}"
  sudo=""
  [ "$(id -u)" -ne 0 ] && sudo=sudo
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" > /dev/null
fi
