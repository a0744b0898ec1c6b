//! `crm certs dev DIR`: a certificate authority and a server certificate signed by it, to
//! try the coordinator's TLS (`--tls-cert`, `--tls-key`, and `--ca` on its clients) without
//! a real CA. For trying only: the CA's key sits beside the certificates.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, KeyPair,
    KeyUsagePurpose,
};

use super::emit;

#[derive(clap::Subcommand, Debug)]
pub enum CertsCommand {
    /// Write `ca.pem`, `ca.key`, `server.pem` and `server.key` into DIR: a CA and a server
    /// certificate it signed for `localhost`, 127.0.0.1, ::1 and each `--host`.
    Dev(DevArgs),
}

#[derive(clap::Args, Debug)]
pub struct DevArgs {
    /// The folder to write into (created; existing certificate files are not overwritten).
    pub dir: PathBuf,
    /// Another name or address the server certificate is valid for (repeatable), e.g. the
    /// coordinator's host name in a compose network.
    #[arg(long = "host", value_name = "NAME")]
    pub hosts: Vec<String>,
    /// Days the certificates are valid.
    #[arg(long, default_value_t = 365)]
    pub days: u32,
}

pub fn run(command: CertsCommand) -> anyhow::Result<()> {
    match command {
        CertsCommand::Dev(args) => dev(&args),
    }
}

const FILES: [&str; 4] = ["ca.pem", "ca.key", "server.pem", "server.key"];

fn dev(args: &DevArgs) -> anyhow::Result<()> {
    if args.days == 0 || args.days > 3650 {
        bail!("--days: 1 to 3650");
    }
    for host in &args.hosts {
        if host.is_empty() || host.contains(|c: char| c.is_whitespace() || c.is_control()) {
            bail!("--host {host:?}: a host name or an IP address");
        }
    }
    std::fs::create_dir_all(&args.dir)
        .with_context(|| format!("{}: cannot create it", args.dir.display()))?;
    for name in FILES {
        let path = args.dir.join(name);
        if path.exists() {
            bail!(
                "{}: already there; remove it or choose another folder",
                path.display()
            );
        }
    }
    let mut names = vec!["localhost".to_string(), "127.0.0.1".into(), "::1".into()];
    names.extend(args.hosts.iter().cloned());
    let files = make(&names, args.days)?;
    for (name, text) in FILES.iter().zip(&files) {
        write(&args.dir.join(name), text, name.ends_with(".key"))?;
    }
    emit(&format!(
        "wrote {dir}/ca.pem, ca.key, server.pem, server.key (server valid for {names})\n\
         coordinator: crm up --tls-cert {dir}/server.pem --tls-key {dir}/server.key --ca {dir}/ca.pem\n\
         clients:     --ca {dir}/ca.pem, with https:// addresses\n",
        dir = args.dir.display(),
        names = names.join(", "),
    ))
}

/// The four PEM texts: CA certificate, CA key, server certificate, server key.
pub fn make(names: &[String], days: u32) -> anyhow::Result<[String; 4]> {
    let now = time::OffsetDateTime::now_utc();
    let until = now + time::Duration::days(i64::from(days));
    let ca_key = KeyPair::generate().context("generating the CA's key")?;
    let mut ca = CertificateParams::new(Vec::<String>::new())?;
    ca.distinguished_name
        .push(DnType::CommonName, "crm-grasp development CA");
    ca.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    ca.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    ca.not_before = now;
    ca.not_after = until;
    let ca_cert = ca.self_signed(&ca_key).context("signing the CA")?;
    let key = KeyPair::generate().context("generating the server's key")?;
    let mut server =
        CertificateParams::new(names.to_vec()).context("--host: not a valid name or address")?;
    server
        .distinguished_name
        .push(DnType::CommonName, "crm-grasp coordinator");
    server.key_usages = vec![KeyUsagePurpose::DigitalSignature];
    server.extended_key_usages = vec![ExtendedKeyUsagePurpose::ServerAuth];
    server.not_before = now;
    server.not_after = until;
    let cert = server
        .signed_by(&key, &ca_cert, &ca_key)
        .context("signing the server certificate")?;
    Ok([
        ca_cert.pem(),
        ca_key.serialize_pem(),
        cert.pem(),
        key.serialize_pem(),
    ])
}

fn write(path: &Path, text: &str, secret: bool) -> anyhow::Result<()> {
    use std::io::Write;
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    if secret {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    let mut file = options
        .open(path)
        .with_context(|| format!("{}: cannot create it", path.display()))?;
    file.write_all(text.as_bytes())
        .with_context(|| format!("{}: cannot write it", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The server certificate is what the coordinator's TLS loads, and its CA is what
    /// clients check it against.
    #[test]
    fn dev_certificates_load_as_the_coordinators_identity() {
        let [ca, _, cert, key] = make(&["localhost".into(), "127.0.0.1".into()], 2).expect("make");
        assert!(ca.starts_with("-----BEGIN CERTIFICATE-----"));
        let dir = std::env::temp_dir().join(format!("crm-certs-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let (cert_path, key_path) = (dir.join("server.pem"), dir.join("server.key"));
        std::fs::write(&cert_path, cert).expect("write");
        std::fs::write(&key_path, key).expect("write");
        crm_server::tls::Identity::load(&cert_path, &key_path).expect("the identity loads");
        // A key that is not the certificate's is refused, naming both files.
        let [_, other_key, _, _] = make(&["localhost".into()], 2).expect("make");
        std::fs::write(&key_path, other_key).expect("write");
        let err = crm_server::tls::Identity::load(&cert_path, &key_path)
            .err()
            .expect("refused");
        assert!(format!("{err:#}").contains("does not fit"), "{err:#}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
