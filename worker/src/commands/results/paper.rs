//! The paper's Table I (section V-B, five training runs each, 1,000 evaluation tasks per model),
//! as the report prints it beside ours.

/// The paper's Table I: (objective, [(IPPO), (LPPO), (CRM-SAC), (CRM-PPO)]) as
/// (success rate, episode length).
const PAPER: [(&str, [(f64, f64); 4]); 8] = [
    (
        "lift",
        [
            (0.85, 412.63),
            (0.88, 456.33),
            (0.63, 534.68),
            (0.88, 342.43),
        ],
    ),
    (
        "pull",
        [(0.86, 433.60), (0.76, 315.82), (1.0, 276.22), (1.0, 217.34)],
    ),
    (
        "press",
        [
            (0.76, 415.82),
            (0.29, 793.22),
            (0.33, 787.64),
            (0.96, 167.30),
        ],
    ),
    (
        "twist",
        [
            (0.74, 436.20),
            (0.67, 531.34),
            (0.49, 599.17),
            (0.91, 335.52),
        ],
    ),
    (
        "lever",
        [
            (0.70, 466.80),
            (0.90, 367.67),
            (0.95, 307.24),
            (0.93, 246.15),
        ],
    ),
    (
        "wrap_grasp",
        [
            (0.89, 348.88),
            (0.67, 372.49),
            (0.60, 377.41),
            (1.0, 252.17),
        ],
    ),
    (
        "handle_grasp",
        [
            (0.98, 303.70),
            (0.97, 369.71),
            (0.75, 338.43),
            (0.97, 281.09),
        ],
    ),
    (
        "overall",
        [
            (0.84, 390.86),
            (0.71, 461.75),
            (0.61, 479.36),
            (0.95, 273.07),
        ],
    ),
];

/// The paper's numbers for `algorithm` on `objective`.
pub fn paper(algorithm: &str, objective: &str) -> Option<(f64, f64)> {
    let column = ["ippo", "lppo", "crm-sac", "crm-ppo"]
        .iter()
        .position(|a| *a == algorithm)?;
    PAPER
        .iter()
        .find(|(o, _)| *o == objective)
        .map(|(_, cells)| cells[column])
}

/// The paper's algorithms in Table I's order (its ranking: CRM-PPO 0.95 > IPPO 0.84 > LPPO
/// 0.71 > CRM-SAC 0.61).
pub const PAPER_ORDER: [&str; 4] = ["crm-ppo", "ippo", "lppo", "crm-sac"];
