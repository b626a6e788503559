# rackd: a release build, then a runtime image with the binary, a default configuration and
# nothing else it does not need.
#
#   docker build -t rackd .
#   podman build --format docker -t rackd .    # podman/buildah: without --format docker the
#                                              # image is OCI, which has no HEALTHCHECK
#
# Base images are pinned by version tag and digest; both are build arguments so that a
# machine without Docker Hub can build from images it provides itself
# (container/local-bases.sh, see docs/operations/container.md). To move to newer bases, change the tag and
# the digest together (`docker buildx imagetools inspect IMAGE:TAG` shows the digest).
# No ENV here sets configuration: the configuration file is the one place it comes from.
ARG RUST_IMAGE=docker.io/library/rust:1.95.0-bookworm@sha256:6258907abe69656e41cd992e0b705cdcfabcbbe3db374f92ed2d47121282d4a1
ARG RUNTIME_IMAGE=docker.io/library/debian:bookworm-20260824-slim@sha256:88200866dfff7ea7f5cbcb6ec7c8a701889efe6fe859fe64d6990e4b07ea4171

FROM ${RUST_IMAGE} AS build
WORKDIR /src
# The dependencies first, against placeholder sources: this layer is rebuilt only when
# Cargo.toml or Cargo.lock change, so a change to rackd's own code recompiles rackd alone.
# (examples/ stays out of the context, but Cargo.toml names the bench example.)
COPY Cargo.toml Cargo.lock ./
COPY .cargo .cargo
RUN mkdir -p src examples/bench \
    && echo 'fn main() {}' > src/main.rs \
    && touch src/lib.rs \
    && echo 'fn main() {}' > examples/bench/main.rs \
    && cargo build --release --locked --bin rackd \
    && rm -rf src target/release/rackd* target/release/deps/rackd-* target/release/deps/librackd-* \
        target/release/.fingerprint/rackd-*
COPY src src
COPY migrations migrations
COPY openapi openapi
COPY config config
# COPY keeps the files' own times, which can be older than the placeholders' build.
RUN touch src/main.rs src/lib.rs \
    && cargo build --release --locked --bin rackd \
    && strip target/release/rackd

FROM ${RUNTIME_IMAGE}
# uid 10001 in group dialout (gid 20 on Debian), which owns the serial ports a site passes
# with --device /dev/ttyUSB0: rackd reaches a serial PLC without running as root.
RUN useradd --system --uid 10001 --gid dialout --home-dir /data --no-create-home \
        --shell /usr/sbin/nologin rackd \
    && mkdir -p /data /etc/rackd \
    && chown 10001:dialout /data
COPY --from=build /src/target/release/rackd /usr/local/bin/rackd
COPY config/container.toml /etc/rackd/rackd.toml
COPY config/rackd.example.toml /etc/rackd/rackd.example.toml
USER 10001:dialout
WORKDIR /data
VOLUME ["/data"]
EXPOSE 8080
# /healthz on the port of config/container.toml: a site that listens elsewhere inside the
# container changes this check too (compose.yaml shows how).
HEALTHCHECK --interval=10s --timeout=5s --start-period=10s --retries=3 \
    CMD ["rackd", "healthcheck", "--url", "http://127.0.0.1:8080/healthz"]
ENTRYPOINT ["rackd"]
CMD ["serve", "--config", "/etc/rackd/rackd.toml"]
