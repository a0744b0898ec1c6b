# Builds the `crm` command. The training service (coordinator, workers) will extend this image.
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release -p crm-worker

FROM debian:bookworm-slim
COPY --from=build /src/target/release/crm /usr/local/bin/crm
ENTRYPOINT ["crm"]
CMD ["oracle"]
