//! `crm serve-policy`: the `Policy` gRPC service over one checkpoint, for a robot or a remote
//! evaluator. The caller sends the environment's full observation and its CRM stage; the
//! service applies the stage's state abstraction and returns the deterministic action (zero
//! outside the stage's action set), the stage and the critic's value.

use std::path::Path;
use std::sync::Mutex;

use crm_proto::pb;
use crm_proto::pb::policy_server::{Policy, PolicyServer};
use crm_server::errors::ErrorKind;
use grasp_sim::observation::{ACTIONS, FEATURES};
use tonic::{Request, Response, Status};

use crm_run::Env;
use crm_run::eval::LoadedPolicy;

pub struct PolicyService {
    policy: Mutex<LoadedPolicy>,
    info: pb::PolicyInfo,
}

impl PolicyService {
    /// Loads `path` for the world of `env` (its hand, spec and sensors must be the ones the
    /// checkpoint was trained with).
    pub fn load(path: &Path, env: &Env) -> anyhow::Result<Self> {
        let policy = LoadedPolicy::load(path, env, &env.config()?)?;
        let machine = &policy.machine;
        let info = pb::PolicyInfo {
            algorithm: policy.algorithm.clone(),
            trained_steps: policy.trained_steps,
            spec_hash: machine.spec().hash(),
            env_version: grasp_sim::ENV_VERSION.into(),
            features: FEATURES.iter().map(|s| s.to_string()).collect(),
            actions: ACTIONS.iter().map(|s| s.to_string()).collect(),
            stages: (0..machine.stage_count())
                .map(|s| machine.stage_name(s).to_string())
                .collect(),
            initial_stage: machine.stage_name(machine.initial()).to_string(),
        };
        Ok(Self {
            policy: Mutex::new(policy),
            info,
        })
    }

    pub fn into_server(self) -> PolicyServer<Self> {
        PolicyServer::new(self)
    }

    /// The action, stage name and value for one request.
    pub fn act(&self, request: &pb::ActRequest) -> Result<pb::ActReply, Status> {
        if request.observation.len() != FEATURES.len() {
            return Err(ErrorKind::InvalidField.status(format!(
                "observation: expected {} values, got {}",
                FEATURES.len(),
                request.observation.len()
            )));
        }
        if let Some(k) = request.observation.iter().position(|v| !v.is_finite()) {
            return Err(ErrorKind::InvalidField
                .status(format!("observation[{k}] ({}) is not finite", FEATURES[k])));
        }
        let mut guard = self
            .policy
            .lock()
            .map_err(|_| ErrorKind::Internal.status("policy lock poisoned"))?;
        let policy = &mut *guard;
        let machine = &policy.machine;
        let stage = if request.stage.is_empty() {
            machine.initial()
        } else {
            machine.stage_id(&request.stage).ok_or_else(|| {
                ErrorKind::InvalidField.status(format!(
                    "stage: unknown stage {:?} (one of {})",
                    request.stage,
                    self.info.stages.join(", ")
                ))
            })?
        };
        if machine.is_terminal(stage) {
            return Err(ErrorKind::InvalidField.status(format!(
                "stage: {} is terminal; the episode is over",
                machine.stage_name(stage)
            )));
        }
        let internal = |e: &dyn std::fmt::Display| ErrorKind::Internal.status(e.to_string());
        let state = machine
            .abstract_state(stage, &request.observation)
            .map_err(|e| internal(&e))?;
        let mask = machine.action_mask(stage);
        let stage_name = machine.stage_name(stage).to_string();
        // A robot gets the deterministic action: the same observation, the same command.
        let action = policy
            .act(&state, stage, &mask, None)
            .map_err(|e| internal(&e))?;
        let value = policy
            .value(&state, stage, &mask)
            .map_err(|e| internal(&e))?;
        Ok(pb::ActReply {
            action,
            stage: stage_name,
            value,
        })
    }
}

#[tonic::async_trait]
impl Policy for PolicyService {
    async fn describe(
        &self,
        _: Request<pb::DescribeRequest>,
    ) -> Result<Response<pb::PolicyInfo>, Status> {
        Ok(Response::new(self.info.clone()))
    }

    async fn act(
        &self,
        request: Request<pb::ActRequest>,
    ) -> Result<Response<pb::ActReply>, Status> {
        Ok(Response::new(PolicyService::act(self, request.get_ref())?))
    }
}

/// `crm serve-policy`'s entry: serves until ctrl-c.
/// Who may call a policy server, and over what: a bearer token (none: anyone who reaches the
/// address) and TLS (`--tls-cert`, `--tls-key`).
pub struct Access {
    tokens: crm_server::auth::Tokens,
    identity: Option<crm_server::tls::Identity>,
}

impl Access {
    pub fn new(
        token: Option<String>,
        tls: Option<(std::path::PathBuf, std::path::PathBuf)>,
    ) -> anyhow::Result<Self> {
        let tokens = crm_server::auth::Tokens::all(token.as_deref())
            .map_err(|e| anyhow::anyhow!("--{e:#}"))?;
        let identity = match tls {
            Some((cert, key)) => Some(crm_server::tls::Identity::load(&cert, &key)?),
            None => None,
        };
        Ok(Self { tokens, identity })
    }
}

pub fn serve_main(
    checkpoint: &Path,
    listen: &str,
    env: &Env,
    access: Access,
) -> anyhow::Result<()> {
    crm_server::init_logging();
    let service = PolicyService::load(checkpoint, env)?;
    let addr: std::net::SocketAddr = listen
        .parse()
        .map_err(|e| anyhow::anyhow!("--listen: {listen:?} is not an address ({e})"))?;
    let runtime = tokio::runtime::Runtime::new()?;
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(addr).await?;
        let bound = listener.local_addr()?;
        let scheme = if access.identity.is_some() {
            "https"
        } else {
            "http"
        };
        println!(
            "crm serve-policy: gRPC Policy on {scheme}://{bound} ({}){}",
            service.info.algorithm,
            if access.tokens.enabled() {
                ", token required"
            } else {
                ""
            }
        );
        let check = crm_server::grpc::TokenCheck::new(access.tokens, crm_server::auth::Scope::Read);
        let mut builder = tonic::transport::Server::builder();
        if let Some(identity) = &access.identity {
            builder = builder.tls_config(identity.grpc())?;
        }
        builder
            .add_service(tonic::service::interceptor::InterceptedService::new(
                service.into_server(),
                check,
            ))
            .serve_with_incoming_shutdown(
                tokio_stream::wrappers::TcpListenerStream::new(listener),
                async {
                    tokio::signal::ctrl_c().await.ok();
                },
            )
            .await?;
        Ok(())
    })
}
