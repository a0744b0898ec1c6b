//! The built-in hand (`worlds/crm/hand.xml` and `hand.json`), compiled in so the binaries run
//! from any folder; loaded by the same code as any other description.

use std::path::Path;
use std::sync::{Arc, OnceLock};

use super::description::Description;
use super::model::HandModel;
use super::profile::Profile;
use crate::error::{Result, parse_json};

/// The built-in hand's MJCF description.
pub const DESCRIPTION: &str = include_str!("../../../../worlds/crm/hand.xml");
/// The built-in hand's profile.
pub const PROFILE: &str = include_str!("../../../../worlds/crm/hand.json");

/// Reads the built-in hand (the crate's tests check it loads).
pub fn load() -> Result<HandModel> {
    let profile: Profile = parse_json(PROFILE, "worlds/crm/hand.json")?;
    let description = Description::from_mjcf(
        DESCRIPTION,
        Path::new("worlds/crm/hand.xml"),
        Path::new("."),
        &crate::assets::Assets::default(),
    )?;
    HandModel::new(&description, &profile, Path::new("worlds/crm/hand.json"))
}

/// The built-in hand, read once per process.
pub fn model() -> Arc<HandModel> {
    static MODEL: OnceLock<Arc<HandModel>> = OnceLock::new();
    MODEL
        .get_or_init(|| match load() {
            Ok(model) => Arc::new(model),
            Err(err) => panic!("the built-in hand is invalid: {err}"),
        })
        .clone()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hand::coupled_angles;
    use crate::taxonomy::Topology;

    #[test]
    fn the_builtin_hand_loads_with_the_papers_coupling() {
        let model = load().expect("built-in hand");
        assert_eq!(model.links.len(), 1 + 2 + 4 * 3);
        assert_eq!(model.joints.len(), 14);
        assert_eq!(model.links[0].name, "palm");
        assert_eq!(model.links[1].name, "thumb_proximal");
        assert_eq!(model.links[2].name, "thumb_distal");
        for (f, finger) in model.fingers.iter().enumerate() {
            let ratios: Vec<f32> = finger.coupled.iter().map(|c| c.1).collect();
            assert_eq!(ratios, coupled_angles(f, 1.0), "finger {f}");
        }
        assert_eq!(model.max_command(0), 2.1);
        assert_eq!(model.max_command(1), 1.7);
        assert!((model.links[0].mass - 0.4).abs() < 1e-6);
        let pinch = model.shape(Topology::PPdAb2);
        assert!(pinch[0].active && pinch[1].active && !pinch[2].active);
        assert_eq!(pinch[0].closed, 1.9);
        assert_eq!(model.shape(Topology::InSiAd2)[1].closed, 1.7);
    }
}
