# Two binaries in one image: `crm-server` (the coordinator) and `crm` (workers, CLI), with the
# shipped models, which the coordinator registers on a new data folder.
#
# With a registry (the official images):
#   docker build -t crm-grasp .            # or `docker compose build`
# Without one (scripts/compose-test, on binaries `cargo build --release` already made):
#   DOCKER_BUILDKIT=1 docker build --build-arg RUNTIME_IMAGE=crm-base:bookworm \
#     --build-arg BINARIES=prebuilt -t crm-grasp .     # reads dist/crm and dist/crm-server
# BuildKit builds only the stages the result needs, so `prebuilt` never starts the Rust image.

# The image that compiles, and the one the binaries run in (the same Debian release, so the
# glibc the binaries link is there).
ARG RUST_IMAGE=rust:1.95-bookworm
ARG RUNTIME_IMAGE=debian:bookworm-slim
# Where the binaries come from: `build` (compiled here) or `prebuilt` (dist/ in the context).
ARG BINARIES=build

FROM ${RUST_IMAGE} AS build
WORKDIR /src
COPY . .
RUN cargo build --release -p crm-server -p crm-worker \
    && mkdir -p /dist && cp target/release/crm target/release/crm-server /dist/

FROM ${RUNTIME_IMAGE} AS prebuilt
COPY dist/crm dist/crm-server /dist/

FROM ${BINARIES} AS binaries

FROM ${RUNTIME_IMAGE}
COPY --from=binaries /dist/crm /dist/crm-server /usr/local/bin/
COPY models /models
VOLUME /data
EXPOSE 8080 50051
ENTRYPOINT ["crm"]
CMD ["--help"]
