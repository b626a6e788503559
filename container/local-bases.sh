#!/usr/bin/env bash
# Provides the Dockerfile's two base images where Docker Hub cannot be reached (the
# machines this project is developed on reach Debian's mirror and crates.io, and nothing
# else): a Debian bookworm root made with debootstrap is the runtime base, and the same
# root with gcc plus this machine's own Rust toolchain is the build base. Both are imported
# into podman under localhost/ names, and the script ends by printing the `podman build`
# command that uses them. A site with Docker Hub needs none of this: the Dockerfile's
# defaults are the pinned official images.
#
# Needs root (debootstrap), podman and debootstrap (`apt-get install -y podman debootstrap`).
# Environment: MIRROR (a Debian mirror, default deb.debian.org), WORK (scratch folder,
# default /var/tmp/rackd-bases, removed at the end), RUSTC (the toolchain to copy: the one
# that `rustc` runs by default).
set -euo pipefail

suite=bookworm
mirror=${MIRROR:-http://deb.debian.org/debian}
work=${WORK:-/var/tmp/rackd-bases}
rustc=${RUSTC:-rustc}
path=/usr/local/cargo/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin

for tool in debootstrap podman "$rustc"; do
    command -v "$tool" >/dev/null || { echo "local-bases: $tool is missing (apt-get install -y podman debootstrap)" >&2; exit 1; }
done
[ "$(id -u)" -eq 0 ] || { echo "local-bases: debootstrap needs root" >&2; exit 1; }

rust_version=$("$rustc" --version | awk '{print $2}')
sysroot=$("$rustc" --print sysroot)
target=$("$rustc" -vV | sed -n 's/^host: //p')
runtime_image=localhost/rackd-base/debian:$suite-slim
build_image=localhost/rackd-base/rust:$rust_version-$suite

rm -rf "$work"
mkdir -p "$work/debs"

# A minimal root, trimmed as the official -slim image is: no apt lists, caches, docs or
# manuals (the runtime image never runs apt).
bootstrap() { # DIR [EXTRA PACKAGES]
    debootstrap --variant=minbase --cache-dir="$work/debs" ${2:+--include="$2"} "$suite" "$1" "$mirror"
    rm -rf "$1"/var/lib/apt/lists/* "$1"/var/cache/apt/*.bin "$1"/var/cache/apt/archives/*.deb \
        "$1"/usr/share/doc/* "$1"/usr/share/man/* "$1"/usr/share/info/*
}

# The runtime base.
bootstrap "$work/runtime"
tar -C "$work/runtime" --numeric-owner -c . |
    podman import --change "ENV PATH=$path" --change 'CMD ["bash"]' - "$runtime_image"

# The build base: gcc is rustc's linker; ca-certificates lets cargo fetch from crates.io.
# The toolchain goes where the official rust image keeps it (RUSTUP_HOME, CARGO_HOME), its
# documentation left out.
bootstrap "$work/build" ca-certificates,gcc,libc6-dev
# This machine's own certificate authorities (here, the one of the proxy through which
# crates.io is reached) are trusted in the build stage as they are on the machine.
if compgen -G "/usr/local/share/ca-certificates/*.crt" >/dev/null; then
    cp /usr/local/share/ca-certificates/*.crt "$work/build/usr/local/share/ca-certificates/"
    chroot "$work/build" update-ca-certificates
fi
toolchain=/usr/local/rustup/toolchains/$rust_version-$target
mkdir -p "$work/build$toolchain" "$work/build/usr/local/cargo/bin"
tar -C "$sysroot" --exclude=./share/doc -c . | tar -C "$work/build$toolchain" -x
for bin in cargo rustc rustdoc; do
    ln -s "$toolchain/bin/$bin" "$work/build/usr/local/cargo/bin/$bin"
done
tar -C "$work/build" --numeric-owner -c . |
    podman import --change "ENV PATH=$path" --change "ENV RUSTUP_HOME=/usr/local/rustup" \
        --change "ENV CARGO_HOME=/usr/local/cargo" --change 'CMD ["bash"]' - "$build_image"

rm -rf "$work"
podman image ls --filter 'reference=localhost/rackd-base/*'
echo
echo "Base images ready. Build rackd with:"
echo "  podman build --format docker --build-arg RUST_IMAGE=$build_image \\"
echo "      --build-arg RUNTIME_IMAGE=$runtime_image -t rackd ."
