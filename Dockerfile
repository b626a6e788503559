# rackd: multi-stage release build; the runtime image holds the binary and nothing else it
# does not need. Build: docker build -t rackd .
FROM rust:1-bookworm AS build
WORKDIR /src
COPY Cargo.toml Cargo.lock ./
COPY src src
COPY migrations migrations
COPY openapi openapi
COPY config config
RUN cargo build --release --locked && strip target/release/rackd

FROM debian:bookworm-slim
RUN useradd --system --uid 10001 --home-dir /data rackd \
    && mkdir -p /data /etc/rackd && chown rackd /data
COPY --from=build /src/target/release/rackd /usr/local/bin/rackd
COPY config/rackd.example.toml /etc/rackd/rackd.example.toml
USER rackd
WORKDIR /data
VOLUME ["/data"]
ENV RACKD_DATABASE=/data/rackd.db \
    RACKD_LISTEN=0.0.0.0:8080 \
    RACKD_HEALTHCHECK_URL=http://127.0.0.1:8080
EXPOSE 8080
HEALTHCHECK --interval=10s --timeout=5s --start-period=10s --retries=3 \
    CMD ["rackd", "healthcheck"]
ENTRYPOINT ["rackd"]
CMD ["serve"]
