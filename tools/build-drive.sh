#!/usr/bin/env bash
# agvrl-drive as shipped: static (glibc, +crt-static), profile `deploy` (fat LTO, stripped),
# inference only (agvrl-rl without its `train` and `ndarray` features).
#
#   tools/build-drive.sh [x86_64|aarch64]      (default: this machine's architecture)
#
# DRIVE_PROFILE=deploy-check builds the same binary in the profile CI checks (fat LTO over 16
# codegen units instead of one: minutes sooner cold, a binary a little larger).
# DRIVE_SETUP_ONLY=1 installs what the build needs and stops (CI then builds in the background).
#
# aarch64 is cross-built with Debian's rustc/cargo (rustc-web, with the arm64 std) and
# aarch64-linux-gnu-gcc, into its own target directory beside the x86_64 one; the packages are
# installed when missing and this runs as root. Prints the binary's path and size (last line:
# `drive_binary=PATH size_mb=N arch=ARCH`).
set -euo pipefail
cd "$(dirname "$0")/.."
arch="${1:-$(uname -m)}"
target_root="${CARGO_TARGET_DIR:-$HOME/.cache/agvrl-target}"
flags='-C target-feature=+crt-static'
profile="${DRIVE_PROFILE:-deploy}"

case "$arch" in
  x86_64)
    triple=x86_64-unknown-linux-gnu
    target_dir="$target_root"
    export CARGO_TARGET_X86_64_UNKNOWN_LINUX_GNU_RUSTFLAGS="$flags"
    cargo=(cargo)
    ;;
  aarch64 | arm64)
    arch=aarch64
    triple=aarch64-unknown-linux-gnu
    # Another compiler: its own directory, so neither build evicts the other's artefacts.
    target_dir="${target_root%/}-aarch64"
    need=()
    [ -x /usr/bin/cargo ] && [ -x /usr/bin/rustc ] || need+=(rustc-web cargo-web)
    [ -d /usr/lib/rustlib/aarch64-unknown-linux-gnu/lib ] || need+=(libstd-rust-web-dev:arm64)
    command -v aarch64-linux-gnu-gcc > /dev/null || need+=(gcc-aarch64-linux-gnu libc6-dev-arm64-cross)
    [ -f /usr/aarch64-linux-gnu/lib/libc.a ] || need+=(libc6-dev-arm64-cross)
    # Debian 12's qemu (7.2) lacks IP_MULTICAST_IF, which RustDDS sets ("Protocol not
    # available"); 10.0, in bookworm-backports, has it.
    qemu_major() { { qemu-aarch64-static --version 2> /dev/null || true; } | sed -n 's/.*version \([0-9]*\)\..*/\1/p' | head -1; }
    [ "$(qemu_major)" -ge 10 ] 2> /dev/null || need+=(qemu-user-static)
    if [ ${#need[@]} -gt 0 ]; then
      if [ "$(id -u)" != 0 ]; then
        echo "missing packages: ${need[*]} (qemu-user-static >= 10); as root: dpkg --add-architecture arm64 && apt-get update && apt-get install ${need[*]}" >&2
        exit 1
      fi
      echo "installing ${need[*]}" >&2
      dpkg --add-architecture arm64
      apt-get update -q > /dev/null
      DEBIAN_FRONTEND=noninteractive apt-get install -y -q "${need[@]}" > /dev/null
      if ! [ "$(qemu_major)" -ge 10 ] 2> /dev/null; then
        codename=$(. /etc/os-release && echo "$VERSION_CODENAME")
        echo "deb http://deb.debian.org/debian $codename-backports main" > /etc/apt/sources.list.d/agvrl-backports.list
        apt-get update -q > /dev/null
        DEBIAN_FRONTEND=noninteractive apt-get install -y -q -t "$codename-backports" qemu-user-static > /dev/null
      fi
    fi
    # rustup's cargo comes first on PATH; Debian's toolchain is called by its full path.
    export RUSTC=/usr/bin/rustc RUSTDOC=/usr/bin/rustdoc
    export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
    export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUSTFLAGS="$flags"
    export CC_aarch64_unknown_linux_gnu=aarch64-linux-gnu-gcc
    cargo=(/usr/bin/cargo)
    ;;
  *)
    echo "unknown architecture '$arch' (x86_64, aarch64)" >&2
    exit 2
    ;;
esac

[ -z "${DRIVE_SETUP_ONLY:-}" ] || exit 0

start=$(date +%s)
CARGO_TARGET_DIR="$target_dir" "${cargo[@]}" build --locked --profile "$profile" -p agvrl-deploy --bin agvrl-drive --target "$triple" >&2
bin="$target_dir/$triple/$profile/agvrl-drive"
bytes=$(stat -c %s "$bin")
echo "built $bin in $(($(date +%s) - start)) s" >&2
echo "drive_binary=$bin size_mb=$(awk "BEGIN{printf \"%.1f\", $bytes/1e6}") arch=$arch"
