# Two binaries in one image: `crm-server` (the coordinator) and `crm` (workers, CLI).
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release -p crm-server -p crm-worker

FROM debian:bookworm-slim
COPY --from=build /src/target/release/crm /usr/local/bin/crm
COPY --from=build /src/target/release/crm-server /usr/local/bin/crm-server
VOLUME /data
EXPOSE 8080 50051
ENTRYPOINT ["crm"]
CMD ["--help"]
