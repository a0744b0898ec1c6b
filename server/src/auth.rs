//! Who may do what: bearer tokens with scopes (docs/SECURITY.md).
//!
//! - `read`: every `GET`/`HEAD` of the REST API (resources, downloads, recordings, the event
//!   stream), which the dashboard needs;
//! - `submit`: everything else of the REST API (jobs, sweeps, uploads, cancels, deletes), and
//!   reading, so a client sees what it submitted;
//! - `worker`: the gRPC `Coordinator` service that rollout workers call.
//!
//! `--token` (`CRM_TOKEN`) holds every scope, as it always did; `--read-token`,
//! `--submit-token` and `--worker-token` (or their `CRM_*_TOKEN` variables, or
//! `--tokens-file`) hold one each. With no token configured the coordinator is open, for a
//! laptop; with any, nothing but `/healthz` and the dashboard's pages (which hold no data and
//! ask for a token) answers without one. The dashboard reads with a `crm_token` cookie (read
//! scope only: a cookie never submits) and submits with the header. Tokens are compared in
//! constant time and never printed.

use std::path::Path;

use anyhow::{Context, bail};
use serde::Deserialize;

/// What a token may do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scope {
    Read,
    Submit,
    Worker,
}

impl Scope {
    pub fn name(self) -> &'static str {
        match self {
            Self::Read => "read",
            Self::Submit => "submit",
            Self::Worker => "worker",
        }
    }
}

/// The configured tokens.
#[derive(Clone, Default)]
pub struct Tokens {
    all: Option<String>,
    read: Option<String>,
    submit: Option<String>,
    worker: Option<String>,
}

/// Never shows a secret.
impl std::fmt::Debug for Tokens {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let set = |t: &Option<String>| if t.is_some() { "set" } else { "unset" };
        f.debug_struct("Tokens")
            .field("all", &set(&self.all))
            .field("read", &set(&self.read))
            .field("submit", &set(&self.submit))
            .field("worker", &set(&self.worker))
            .finish()
    }
}

/// `--tokens-file`: a JSON object with any of `token`, `read`, `submit`, `worker`.
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct TokensFile {
    token: Option<String>,
    read: Option<String>,
    submit: Option<String>,
    worker: Option<String>,
}

/// The answer to a request's credentials.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    Allowed,
    /// No token, or one the coordinator does not know: 401.
    Unauthenticated,
    /// A known token without the scope: 403.
    Forbidden,
}

impl Tokens {
    /// One token with every scope (tests, and `crm serve-policy --token`), checked as the
    /// coordinator's are.
    pub fn all(token: Option<&str>) -> anyhow::Result<Self> {
        let tokens = Self {
            all: token.map(str::to_string),
            ..Self::default()
        };
        tokens.validate()?;
        Ok(tokens)
    }

    /// The coordinator's tokens: the configuration's, then `--tokens-file`'s for those it
    /// leaves unset. Refuses an empty token, a token given twice for two scopes, and scoped
    /// tokens that leave a scope with none (workers, or clients, could not get in).
    pub fn configured(config: &crate::ServerConfig) -> anyhow::Result<Self> {
        let file = match &config.tokens_file {
            Some(path) => read_file(path)?,
            None => TokensFile::default(),
        };
        let tokens = Self {
            all: config.token.clone().or(file.token),
            read: config.read_token.clone().or(file.read),
            submit: config.submit_token.clone().or(file.submit),
            worker: config.worker_token.clone().or(file.worker),
        };
        tokens.validate()?;
        Ok(tokens)
    }

    fn named(&self) -> [(&'static str, &Option<String>); 4] {
        [
            ("token", &self.all),
            ("read_token", &self.read),
            ("submit_token", &self.submit),
            ("worker_token", &self.worker),
        ]
    }

    fn validate(&self) -> anyhow::Result<()> {
        let named = self.named();
        for (name, token) in named {
            if let Some(token) = token {
                if token.is_empty() {
                    bail!("{name}: must not be empty");
                }
                if !token.bytes().all(|b| b.is_ascii_graphic()) {
                    bail!("{name}: printable ASCII without spaces (it travels in a header)");
                }
            }
        }
        for (i, (a, x)) in named.iter().enumerate() {
            for (b, y) in &named[i + 1..] {
                if x.is_some() && x == y {
                    bail!("{a} and {b}: the same secret; give each scope its own");
                }
            }
        }
        let scoped = self.read.is_some() || self.submit.is_some() || self.worker.is_some();
        if scoped && self.all.is_none() {
            for (name, token) in [
                ("read_token", &self.read),
                ("submit_token", &self.submit),
                ("worker_token", &self.worker),
            ] {
                if token.is_none() {
                    bail!(
                        "{name}: missing; with scoped tokens every scope needs one (or set token, which holds them all)"
                    );
                }
            }
        }
        Ok(())
    }

    /// Whether any token is configured (otherwise everything is open).
    pub fn enabled(&self) -> bool {
        self.named().iter().any(|(_, t)| t.is_some())
    }

    /// What `given` (the bearer token of a request, if any) may do about `scope`.
    pub fn check(&self, given: Option<&str>, scope: Scope) -> Verdict {
        if !self.enabled() {
            return Verdict::Allowed;
        }
        let Some(given) = given else {
            return Verdict::Unauthenticated;
        };
        // Compare against every token, whatever matched first, so timing tells nothing.
        let is = |t: &Option<String>| {
            t.as_deref()
                .is_some_and(|t| crate::secrets::constant_time_eq(given.as_bytes(), t.as_bytes()))
        };
        let (all, read, submit, worker) = (
            is(&self.all),
            is(&self.read),
            is(&self.submit),
            is(&self.worker),
        );
        let allowed = all
            || match scope {
                Scope::Read => read || submit,
                Scope::Submit => submit,
                Scope::Worker => worker,
            };
        if allowed {
            Verdict::Allowed
        } else if read || submit || worker {
            Verdict::Forbidden
        } else {
            Verdict::Unauthenticated
        }
    }

    /// The token local workers use (`crm up`): the worker scope's.
    pub fn for_workers(&self) -> Option<String> {
        self.worker.clone().or_else(|| self.all.clone())
    }
}

fn read_file(path: &Path) -> anyhow::Result<TokensFile> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("--tokens-file {}: cannot read it", path.display()))?;
    serde_json::from_str(&text).with_context(|| {
        format!(
            "--tokens-file {}: a JSON object with any of \"token\", \"read\", \"submit\", \"worker\"",
            path.display()
        )
    })
}

/// The bearer token of an `authorization` header value.
pub fn bearer(value: Option<&str>) -> Option<&str> {
    value.and_then(|v| v.strip_prefix("Bearer "))
}

/// The token of the dashboard's `crm_token` cookie (percent-decoded, as the dashboard
/// encodes it), if the request has one.
pub fn cookie(headers: &axum::http::HeaderMap) -> Option<String> {
    let raw = headers
        .get_all(axum::http::header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .find_map(|pair| pair.trim().strip_prefix("crm_token="))
        .filter(|t| !t.is_empty())?;
    let bytes = raw.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        match (bytes[i], bytes.get(i + 1), bytes.get(i + 2)) {
            (b'%', Some(&h), Some(&l)) if hex(h).is_some() && hex(l).is_some() => {
                out.push(((hex(h)? << 4) | hex(l)?) as u8);
                i += 3;
            }
            (b, _, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8(out).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scoped() -> Tokens {
        Tokens {
            all: None,
            read: Some("read-secret".into()),
            submit: Some("submit-secret".into()),
            worker: Some("worker-secret".into()),
        }
    }

    #[test]
    fn each_token_holds_its_scopes_and_no_other() {
        let t = scoped();
        use Scope::*;
        use Verdict::*;
        assert_eq!(t.check(Some("read-secret"), Read), Allowed);
        assert_eq!(t.check(Some("read-secret"), Submit), Forbidden);
        assert_eq!(t.check(Some("read-secret"), Worker), Forbidden);
        assert_eq!(t.check(Some("submit-secret"), Read), Allowed);
        assert_eq!(t.check(Some("submit-secret"), Submit), Allowed);
        assert_eq!(t.check(Some("submit-secret"), Worker), Forbidden);
        assert_eq!(t.check(Some("worker-secret"), Read), Forbidden);
        assert_eq!(t.check(Some("worker-secret"), Worker), Allowed);
        assert_eq!(t.check(None, Read), Unauthenticated);
        assert_eq!(
            t.check(Some("read-secre"), Read),
            Unauthenticated,
            "a prefix"
        );
        assert_eq!(t.check(Some("wrong"), Read), Unauthenticated);
        let all = Tokens::all(Some("every-scope")).expect("a valid token");
        for scope in [Read, Submit, Worker] {
            assert_eq!(all.check(Some("every-scope"), scope), Allowed);
            assert_eq!(all.check(None, scope), Unauthenticated);
            assert_eq!(Tokens::default().check(None, scope), Allowed);
        }
    }

    #[test]
    fn bad_token_settings_are_refused_by_name() {
        let refused = |t: Tokens| format!("{:#}", t.validate().expect_err("refused"));
        let mut t = scoped();
        t.worker = None;
        assert!(refused(t).starts_with("worker_token: missing"));
        let mut t = scoped();
        t.submit = Some("read-secret".into());
        assert!(refused(t).contains("the same secret"));
        let mut t = scoped();
        t.read = Some(String::new());
        assert!(refused(t).starts_with("read_token: must not be empty"));
        let mut t = scoped();
        t.read = Some("has space".into());
        assert!(refused(t).starts_with("read_token: printable"));
        assert!(format!("{:?}", scoped()).contains("\"set\""));
        assert!(!format!("{:?}", scoped()).contains("secret"));
    }

    #[test]
    fn the_dashboards_cookie_is_found_among_others() {
        let mut headers = axum::http::HeaderMap::new();
        assert_eq!(cookie(&headers), None);
        headers.insert(
            "cookie",
            "theme=dark; crm_token=abc123; x=y".parse().expect("header"),
        );
        assert_eq!(cookie(&headers).as_deref(), Some("abc123"));
        headers.insert("cookie", "crm_token=a%3Bb%25c".parse().expect("header"));
        assert_eq!(cookie(&headers).as_deref(), Some("a;b%c"));
        headers.insert("cookie", "crm_token=".parse().expect("header"));
        assert_eq!(cookie(&headers), None);
    }
}
