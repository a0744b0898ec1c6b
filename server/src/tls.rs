//! TLS for both listeners (`--tls-cert`, `--tls-key`): rustls with the ring provider. The
//! REST listener wraps each connection itself (`listen.rs`); the gRPC listener hands the same
//! PEM files to tonic. `crm certs dev DIR` makes a CA and a certificate to try it with.

use std::path::Path;
use std::sync::Arc;

use anyhow::{Context, bail};
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};

/// The certificate chain and key, as PEM text and as rustls's server configuration.
#[derive(Clone)]
pub struct Identity {
    pub cert_pem: Vec<u8>,
    pub key_pem: Vec<u8>,
    /// For the REST listener: HTTP/2 and HTTP/1.1 by ALPN.
    pub rest: Arc<rustls::ServerConfig>,
}

impl Identity {
    /// Reads and checks `cert` (a PEM chain, the server's first) and `key` (PEM, PKCS#8,
    /// PKCS#1 or SEC1); errors name the file and what is wrong.
    pub fn load(cert: &Path, key: &Path) -> anyhow::Result<Self> {
        let cert_pem = std::fs::read(cert)
            .with_context(|| format!("--tls-cert {}: cannot read it", cert.display()))?;
        let key_pem = std::fs::read(key)
            .with_context(|| format!("--tls-key {}: cannot read it", key.display()))?;
        let chain = CertificateDer::pem_slice_iter(&cert_pem)
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| anyhow::anyhow!("--tls-cert {}: {e}", cert.display()))?;
        if chain.is_empty() {
            bail!("--tls-cert {}: no PEM certificate in it", cert.display());
        }
        let private = PrivateKeyDer::from_pem_slice(&key_pem).map_err(|e| {
            anyhow::anyhow!("--tls-key {}: no PEM private key ({e})", key.display())
        })?;
        let provider = Arc::new(rustls::crypto::ring::default_provider());
        let mut rest = rustls::ServerConfig::builder_with_provider(provider)
            .with_safe_default_protocol_versions()
            .context("TLS protocol versions")?
            .with_no_client_auth()
            .with_single_cert(chain, private)
            .with_context(|| {
                format!(
                    "--tls-key {} does not fit --tls-cert {}",
                    key.display(),
                    cert.display()
                )
            })?;
        rest.alpn_protocols = vec![b"h2".to_vec(), b"http/1.1".to_vec()];
        Ok(Self {
            cert_pem,
            key_pem,
            rest: Arc::new(rest),
        })
    }

    /// tonic's form of the same identity, for the gRPC listener.
    pub fn grpc(&self) -> tonic::transport::ServerTlsConfig {
        tonic::transport::ServerTlsConfig::new().identity(tonic::transport::Identity::from_pem(
            &self.cert_pem,
            &self.key_pem,
        ))
    }
}
