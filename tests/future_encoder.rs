//! The unified policy's future encoder as the paper's RNN (`policy.scan_encoder.kind:
//! gru`): a GRU over the plan's predicted states, in order. The foundation
//! transfers into it acting the same, a tiny unified run trains with it, the
//! order of the plan's states matters to it, and a step that does not divide
//! the plan is refused.
mod common;

use dreampolicy::env::obs::OBS_DIM;
use dreampolicy::rl::checkpoint::Checkpoint;
use dreampolicy::rl::{Agent, VecTask};

const GRU: [&str; 3] = [
    "policy.scan_encoder.kind=gru",
    "policy.scan_encoder.step=98",
    "policy.scan_encoder.gru_hidden=24",
];

#[test]
fn the_foundation_transfers_into_a_gru_future_encoder_acting_the_same() {
    let mut sets = vec!["env.n_envs=3"];
    sets.extend(GRU);
    let cfg = common::load_config("unified/small.yaml", &sets);
    let (mut task, mut old, mut new, t) = common::foundation_into_unified(&cfg);
    assert_eq!(task.dims().scan, 8 * OBS_DIM);
    assert_eq!(t.widened, ["actor.0.weight", "critic.0.weight"]);
    // the GRU's own tensors start fresh
    assert!(t
        .fresh
        .iter()
        .any(|n| n.starts_with("scan_actor.weight_ih")));
    let w = new
        .policy
        .named_parameters()
        .into_iter()
        .find(|(n, _)| n == "actor.0.weight")
        .unwrap()
        .1;
    // [hist 64, future latent 24, obs 98]
    assert_eq!(w.size()[1], 64 + 24 + OBS_DIM as i64);
    common::assert_acts_alike(&mut old, &mut new, &mut task, 6);

    // the encoder reads a sequence: reversing the plan's states changes its latent
    let policy = &new.policy;
    tch::manual_seed(3);
    let plan = tch::Tensor::randn(
        [2, 8 * OBS_DIM as i64],
        (tch::Kind::Float, tch::Device::Cpu),
    );
    let reversed = plan
        .reshape([2, 8, OBS_DIM as i64])
        .flip([1])
        .reshape([2, -1]);
    let latent = |x: &tch::Tensor| policy.scan_latent(x).unwrap();
    let (a, b) = (latent(&plan), latent(&reversed));
    assert_eq!(a.size(), [2, 24]);
    let d = (a - b).abs().max().double_value(&[]);
    assert!(
        d > 1e-4,
        "the future encoder ignores the order of the plan ({d})"
    );
}

#[test]
fn a_tiny_unified_run_trains_with_a_gru_future_encoder() {
    let cfg = common::load_config(
        "test/unified_tiny.yaml",
        &[
            "policy.scan_encoder.kind=gru",
            "policy.scan_encoder.step=98",
            "policy.scan_encoder.gru_hidden=16",
        ],
    );
    let dir = common::Scratch::new("uni-gru");
    dreampolicy::unified::train(&cfg, &dir.0, false, true).unwrap();
    let ck = Checkpoint::read(&dreampolicy::run::latest_checkpoint(&dir.0)).unwrap();
    assert_eq!(ck.meta.iteration, 4);
    // the checkpoint holds the GRU and loads back into the same architecture
    let mut agent = Agent::new(&cfg.policy, ck.meta.dims, 1, true);
    ck.load_agent(&mut agent).unwrap();
    let names: Vec<String> = agent
        .policy
        .named_parameters()
        .into_iter()
        .map(|(n, _)| n)
        .collect();
    assert!(
        names.iter().any(|n| n == "scan_critic.weight_hh_l0"),
        "{names:?}"
    );

    // the exported bundle's TorchScript policy runs the GRU and gives the
    // agent's actions, for any batch size
    let out = common::Scratch::new("uni-gru-export");
    dreampolicy::unified::export::write_bundle(&ck, &out.0).unwrap();
    let module = tch::CModule::load(out.0.join("policy.pt")).unwrap();
    agent.set_frozen(true);
    let d = ck.meta.dims;
    let (od, sd) = (d.obs, d.scan);
    for rows in [1usize, 3] {
        tch::manual_seed(rows as i64);
        let f = tch::kind::FLOAT_CPU;
        let obs = tch::Tensor::randn([rows as i64, od as i64], f);
        let hist = tch::Tensor::randn([rows as i64, 3, od as i64], f);
        let plan = tch::Tensor::randn([rows as i64, sd as i64], f);
        let theirs = module
            .forward_ts(&[
                obs.shallow_clone(),
                hist.shallow_clone(),
                plan.shallow_clone(),
            ])
            .unwrap();
        // the agent's own normalization, row by row, then its networks
        let raw = |t: &tch::Tensor| Vec::<f32>::try_from(t.contiguous().view([-1])).unwrap();
        let (o, h, p) = (raw(&obs), raw(&hist), raw(&plan));
        let mut a_in = vec![0f32; rows * 4 * od];
        let mut s_in = vec![0f32; rows * sd];
        for r in 0..rows {
            for j in 0..4 {
                let src = if j < 3 {
                    &h[(r * 3 + j) * od..(r * 3 + j + 1) * od]
                } else {
                    &o[r * od..(r + 1) * od]
                };
                let at = (r * 4 + j) * od;
                agent.obs_norm.apply(src, &mut a_in[at..at + od]);
            }
            agent
                .scan_norm
                .apply(&p[r * sd..(r + 1) * sd], &mut s_in[r * sd..(r + 1) * sd]);
        }
        let ours = tch::no_grad(|| {
            agent.policy.actor_mean(
                &tch::Tensor::from_slice(&a_in).view([rows as i64, -1]),
                Some(&tch::Tensor::from_slice(&s_in).view([rows as i64, sd as i64])),
            )
        });
        let worst = (theirs - ours).abs().max().double_value(&[]);
        assert!(worst < 1e-5, "batch {rows}: policy.pt differs by {worst}");
    }

    // a step that does not divide the plan (4 states of 98) is refused in one line
    let bad = common::load_config(
        "test/unified_tiny.yaml",
        &[
            "policy.scan_encoder.kind=gru",
            "policy.scan_encoder.step=97",
        ],
    );
    let dir = common::Scratch::new("uni-gru-bad");
    let e = dreampolicy::unified::train(&bad, &dir.0, false, true)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("scan_encoder.step 97") && e.contains("392"),
        "{e}"
    );
}
