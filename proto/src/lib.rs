//! The crm-grasp gRPC protocol, generated from `crm_grasp.proto` at build time with protox
//! (a pure-Rust protobuf compiler), so no system `protoc` is needed: the `Coordinator`
//! service workers call, and the `Policy` service for remote inference.

/// Generated messages, clients and servers (package `crm_grasp.v1`).
#[allow(clippy::all, missing_docs)]
pub mod pb {
    tonic::include_proto!("crm_grasp.v1");
}
