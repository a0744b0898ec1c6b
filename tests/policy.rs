//! End-to-end test of `crm serve-policy`: the `Policy` gRPC service over a checkpoint, behind
//! a token.

mod support;

use crm_proto::pb;
use crm_proto::pb::policy_client::PolicyClient;
use support::*;

#[test]
fn the_policy_service_acts_and_refuses_bad_observations() {
    let dir = TempDir::new("policy");
    let status = std::process::Command::new(crm())
        .args([
            "train",
            "--task",
            "mouse-press",
            "--steps",
            "256",
            "--envs",
            "1",
            "--out",
        ])
        .arg(&dir.0)
        .stderr(std::process::Stdio::null())
        .status()
        .expect("train");
    assert!(status.success());
    let checkpoint = dir.0.join("crm-ppo.safetensors");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("free port")
        .port();
    let mut child = std::process::Command::new(crm())
        .args([
            "serve-policy",
            "--listen",
            &format!("127.0.0.1:{port}"),
            "--token",
            TOKEN,
            "--checkpoint",
        ])
        .arg(&checkpoint)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("serve-policy");
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(child.stdout.take().expect("stdout")),
        &mut line,
    )
    .expect("banner");
    let _server = Proc(child);
    assert!(line.contains("Policy"), "{line}");

    let runtime = tokio::runtime::Runtime::new().expect("runtime");
    runtime.block_on(async {
        let channel = tonic::transport::Channel::from_shared(format!("http://127.0.0.1:{port}"))
            .expect("url")
            .connect()
            .await
            .expect("connect");
        // `--token`: a call without it is refused.
        let refused = PolicyClient::new(channel.clone())
            .describe(pb::DescribeRequest {})
            .await
            .expect_err("refused");
        assert_eq!(refused.code(), tonic::Code::Unauthenticated);
        let mut client = PolicyClient::with_interceptor(channel, |mut r: tonic::Request<()>| {
            let bearer = format!("Bearer {TOKEN}").parse().expect("header");
            r.metadata_mut().insert("authorization", bearer);
            Ok(r)
        });
        let info = client
            .describe(pb::DescribeRequest {})
            .await
            .expect("describe")
            .into_inner();
        assert_eq!(info.algorithm, "crm-ppo");
        assert_eq!(info.trained_steps, 256);
        assert_eq!(info.features.len(), 38);
        assert_eq!(info.actions.len(), 8);
        assert_eq!(info.initial_stage, "approach");
        let observation = vec![0.1f32; 38];
        let reply = client
            .act(pb::ActRequest {
                observation: observation.clone(),
                stage: String::new(),
            })
            .await
            .expect("act")
            .into_inner();
        assert_eq!(reply.stage, "approach");
        assert_eq!(reply.action.len(), 8);
        assert!(reply.action.iter().all(|a| a.is_finite()));
        assert!(reply.value.is_finite());
        // Deterministic: the same request gives the same action.
        let again = client
            .act(pb::ActRequest {
                observation: observation.clone(),
                stage: "approach".into(),
            })
            .await
            .expect("act")
            .into_inner();
        assert_eq!(again.action, reply.action);
        let grasp = client
            .act(pb::ActRequest {
                observation: observation.clone(),
                stage: "grasp".into(),
            })
            .await
            .expect("act")
            .into_inner();
        assert_eq!(grasp.stage, "grasp");
        // The fingers only close, by |a|: the deterministic action gives each the sampled
        // action's mean magnitude, which the noise makes positive.
        assert!(
            grasp.action[3..].iter().all(|&a| a > 0.0),
            "{:?}",
            grasp.action
        );
        for (observation, stage, what) in [
            (vec![0.0f32; 37], "", "observation"),
            (vec![f32::NAN; 38], "", "not finite"),
            (vec![0.0f32; 38], "lift", "stage"),
            (vec![0.0f32; 38], "success", "terminal"),
        ] {
            let err = client
                .act(pb::ActRequest {
                    observation,
                    stage: stage.into(),
                })
                .await
                .expect_err(what);
            assert_eq!(err.code(), tonic::Code::InvalidArgument, "{what}: {err}");
            assert!(err.message().contains(what), "{what}: {}", err.message());
        }
    });
}
