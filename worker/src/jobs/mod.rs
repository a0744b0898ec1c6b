//! Jobs the worker runs, shared by the command line (`crm train`, `crm eval`) and the service
//! worker (`crm worker`): a training run that advances one PPO iteration at a time and can
//! resume from a checkpoint, and a checkpoint evaluation over random tasks (Table I).

pub mod eval;
pub mod train;

use crm_api::Algorithm;

/// The reward mode each algorithm learns from (paper, section V-A).
pub fn reward_mode(algorithm: Algorithm) -> crm::RewardMode {
    match algorithm {
        Algorithm::Ippo => crm::RewardMode::Sparse,
        Algorithm::Lppo => crm::RewardMode::Dense,
        _ => crm::RewardMode::Crm,
    }
}
