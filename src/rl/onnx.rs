//! ONNX export of a checkpoint's deterministic actor, normalization included:
//! the same function as the TorchScript file of [`super::export`], with the
//! same inputs `obs [batch, 98]`, `history [batch, K, 98]` (oldest first),
//! `scan [batch, 187]` (raw, unnormalized) and the output `action [batch, 29]`
//! (the action mean). The batch size is free (`batch`).
//!
//! The graph is written node by node from the checkpoint's weights with the
//! `onnx-protobuf` crate's messages (ONNX's own `onnx.proto3`, compiled by
//! rust-protobuf): no Python and no tracing in the path. Operator set
//! [`OPSET`] of the default domain, IR version [`IR_VERSION`]; the ops used are
//! `Sub`, `Div`, `Clip`, `Flatten`, `Reshape`, `Transpose`, `Gemm`, `Elu` /
//! `Relu` / `Tanh`, `GRU`, `Squeeze` and `Concat`, which every ONNX runtime
//! has. A GRU encoder (history or scan) becomes ONNX's `GRU` with
//! `linear_before_reset = 1` (PyTorch's cell), its gate blocks reordered from
//! PyTorch's `(r, z, n)` to ONNX's `(z, r, h)`, and its last hidden state
//! `Y_h` as the latent.
//!
//! The model's `metadata_props` name the dimensions, the history rule and the
//! checkpoint it came from, as mjlab attaches its own to its exported policies.
use std::collections::HashMap;
use std::path::Path;

use onnx_protobuf::{
    attribute_proto::AttributeType, tensor_proto::DataType, tensor_shape_proto, type_proto,
    AttributeProto, GraphProto, Message, ModelProto, NodeProto, OperatorSetIdProto,
    StringStringEntryProto, TensorProto, TensorShapeProto, TypeProto, ValueInfoProto,
};
use serde::Serialize;
use tch::{Kind, Tensor};

use super::agent::Agent;
use super::checkpoint::Checkpoint;
use super::config::{Activation, HistoryKind, ScanEncoderKind};
use super::RlError;

/// The operator set the graph is written for (default ONNX domain).
pub const OPSET: i64 = 17;
/// The ONNX IR version that goes with [`OPSET`].
pub const IR_VERSION: i64 = 8;
/// Names of the graph's inputs and output.
pub const INPUTS: [&str; 3] = ["obs", "history", "scan"];
pub const OUTPUT: &str = "action";

/// What an ONNX export wrote.
#[derive(Debug, Clone, Serialize)]
pub struct OnnxInfo {
    pub path: String,
    pub opset: i64,
    pub ir_version: i64,
    pub obs_dim: usize,
    pub history_len: usize,
    pub history: String,
    pub scan_dim: usize,
    pub scan_encoder: Option<String>,
    pub action_dim: usize,
    pub nodes: usize,
    pub parameters: usize,
}

/// Write the checkpoint's actor as an ONNX file at `out`.
pub fn export_onnx(ck: &Checkpoint, out: &Path) -> Result<OnnxInfo, RlError> {
    let (_, agent) = super::export::checkpoint_agent(ck)?;
    let meta = [
        ("source_checkpoint", ck.path.display().to_string()),
        ("source_iteration", ck.meta.iteration.to_string()),
        ("source_env_steps", ck.meta.env_steps.to_string()),
    ];
    write_actor_onnx(&agent, &meta, out)
}

/// Write `agent`'s deterministic actor (normalization included) as an ONNX
/// file at `out`, with `extra` in the model's metadata.
pub fn write_actor_onnx(
    agent: &Agent,
    extra: &[(&str, String)],
    out: &Path,
) -> Result<OnnxInfo, RlError> {
    let (model, mut info) = actor_model(agent, extra)?;
    let bytes = model
        .write_to_bytes()
        .map_err(|e| RlError::Invalid(format!("ONNX protobuf encoding: {e}")))?;
    if let Some(dir) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|source| RlError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
    }
    crate::run::write_atomic(out, &bytes).map_err(|(path, source)| RlError::Io { path, source })?;
    info.path = out.display().to_string();
    Ok(info)
}

/// The ONNX model of `agent`'s actor, and what it holds (`path` left empty).
pub fn actor_model(
    agent: &Agent,
    extra: &[(&str, String)],
) -> Result<(ModelProto, OnnxInfo), RlError> {
    let policy = &agent.policy;
    if policy.has_estimator() {
        return Err(RlError::Invalid(
            "this policy has a privileged-information estimator (policy.estimator), which the ONNX and NumPy exporters do not write yet: export its TorchScript file alone (`export --file-only`)".into(),
        ));
    }
    let cfg = &policy.cfg;
    let d = agent.dims();
    let k = policy.history_len();
    let vars = policy.vs.variables();
    let mut g = Graph::new(&vars, cfg.activation);

    // inputs, normalized as RunningNorm does: clip((x - mean) / std)
    let (om, os) = agent.obs_norm.tensors();
    let (sm, ss) = agent.scan_norm.tensors();
    let norm = |g: &mut Graph, x: &str, mean: &Tensor, std: &Tensor, clip: f32, tag: &str| {
        if !agent.normalize {
            return x.to_string();
        }
        let m = g.constant(&format!("{tag}_mean"), mean);
        let s = g.constant(&format!("{tag}_std"), std);
        let c = g.scalar(&format!("{tag}_clip"), clip);
        let nc = g.scalar(&format!("{tag}_neg_clip"), -clip);
        let y = g.node("Sub", &[x, &m], vec![]);
        let y = g.node("Div", &[&y, &s], vec![]);
        g.node("Clip", &[&y, &nc, &c], vec![])
    };
    let obs = norm(&mut g, INPUTS[0], &om, &os, agent.obs_norm.clip, "obs");
    let mut parts = Vec::new();
    let history = if k == 0 {
        "none".to_string()
    } else {
        let hist = norm(&mut g, INPUTS[1], &om, &os, agent.obs_norm.clip, "history");
        match cfg.history.kind {
            HistoryKind::None => {}
            HistoryKind::Mlp => {
                let flat = g.node("Flatten", &[&hist], vec![attr_int("axis", 1)]);
                parts.push(g.mlp("hist", &flat, true)?);
            }
            HistoryKind::Gru => {
                let seq = g.node("Transpose", &[&hist], vec![attr_ints("perm", &[1, 0, 2])]);
                parts.push(g.gru("hist", &seq, cfg.history.gru_hidden)?);
            }
        }
        format!("{:?}", cfg.history.kind).to_lowercase()
    };
    let uses_scan = policy.uses_scan();
    let scan_encoder = if uses_scan {
        let scan = norm(&mut g, INPUTS[2], &sm, &ss, agent.scan_norm.clip, "scan");
        let se = &cfg.scan_encoder;
        match se.kind {
            ScanEncoderKind::Mlp => parts.push(g.mlp("scan_actor", &scan, true)?),
            ScanEncoderKind::Gru => {
                let step = se.step.max(1) as i64;
                let steps = d.scan as i64 / step;
                let shape = g.constant_i64("scan_seq_shape", &[-1, steps, step]);
                let seq = g.node("Reshape", &[&scan, &shape], vec![]);
                let seq = g.node("Transpose", &[&seq], vec![attr_ints("perm", &[1, 0, 2])]);
                parts.push(g.gru("scan_actor", &seq, se.gru_hidden)?);
            }
        }
        Some(format!("{:?}", se.kind).to_lowercase())
    } else {
        None
    };
    parts.push(obs);
    let refs: Vec<&str> = parts.iter().map(String::as_str).collect();
    let actor_in = g.node("Concat", &refs, vec![attr_int("axis", 1)]);
    let mean = g.mlp("actor", &actor_in, false)?;
    g.nodes.push(node("Identity", &[&mean], &[OUTPUT], vec![]));

    let batch = Dim::Param("batch");
    let (obs_d, scan_d, act_d) = (d.obs as i64, d.scan as i64, d.action as i64);
    let mut graph = GraphProto::new();
    graph.name = "DreamPolicyActor".into();
    graph.input = vec![
        value_info(INPUTS[0], &[batch, Dim::Value(obs_d)]),
        value_info(INPUTS[1], &[batch, Dim::Value(k as i64), Dim::Value(obs_d)]),
        value_info(INPUTS[2], &[batch, Dim::Value(scan_d)]),
    ];
    graph.output = vec![value_info(OUTPUT, &[batch, Dim::Value(act_d)])];
    let parameters = g.parameters;
    let nodes = g.nodes.len();
    graph.node = g.nodes;
    graph.initializer = g.initializers;
    graph.doc_string = "forward(obs [batch, obs_dim], history [batch, history_len, obs_dim], \
                        scan [batch, scan_dim]) -> action mean [batch, action_dim]; raw inputs, \
                        the normalization is inside"
        .into();

    let mut model = ModelProto::new();
    model.ir_version = IR_VERSION;
    model.producer_name = "dreampolicy".into();
    model.producer_version = env!("CARGO_PKG_VERSION").into();
    model.doc_string = graph.doc_string.clone();
    let mut opset = OperatorSetIdProto::new();
    opset.version = OPSET;
    model.opset_import = vec![opset];
    let mut meta: Vec<(&str, String)> = vec![
        ("obs_dim", d.obs.to_string()),
        ("history_len", k.to_string()),
        ("history_kind", history.clone()),
        ("scan_dim", d.scan.to_string()),
        ("uses_scan", uses_scan.to_string()),
        ("action_dim", d.action.to_string()),
        (
            "history_rule",
            "history holds the history_len observations before the current one, oldest first; \
             at reset all are the first observation; the current observation goes in obs only"
                .into(),
        ),
    ];
    meta.extend(extra.iter().cloned());
    model.metadata_props = meta
        .into_iter()
        .map(|(k, v)| {
            let mut e = StringStringEntryProto::new();
            e.key = k.into();
            e.value = v;
            e
        })
        .collect();
    model.graph = Some(graph).into();
    let info = OnnxInfo {
        path: String::new(),
        opset: OPSET,
        ir_version: IR_VERSION,
        obs_dim: d.obs,
        history_len: k,
        history,
        scan_dim: d.scan,
        scan_encoder,
        action_dim: d.action,
        nodes,
        parameters,
    };
    Ok((model, info))
}

/// A graph under construction: nodes in order, initializers, fresh names.
struct Graph<'a> {
    vars: &'a HashMap<String, Tensor>,
    activation: Activation,
    nodes: Vec<NodeProto>,
    initializers: Vec<TensorProto>,
    parameters: usize,
    next: usize,
}

impl<'a> Graph<'a> {
    fn new(vars: &'a HashMap<String, Tensor>, activation: Activation) -> Graph<'a> {
        Graph {
            vars,
            activation,
            nodes: Vec::new(),
            initializers: Vec::new(),
            parameters: 0,
            next: 0,
        }
    }

    /// Append `op` on `inputs`; its one output's fresh name.
    fn node(&mut self, op: &str, inputs: &[&str], attrs: Vec<AttributeProto>) -> String {
        self.next += 1;
        let out = format!("{}_{}", op.to_lowercase(), self.next);
        self.nodes.push(node(op, inputs, &[&out], attrs));
        out
    }

    /// A float initializer named `name` holding `t` (any shape).
    fn constant(&mut self, name: &str, t: &Tensor) -> String {
        let t = t.to_kind(Kind::Float).contiguous();
        let dims = t.size();
        let data = Vec::<f32>::try_from(t.flatten(0, -1)).unwrap_or_default();
        self.parameters += data.len();
        let mut p = TensorProto::new();
        p.name = name.into();
        p.dims = dims;
        p.data_type = DataType::FLOAT as i32;
        p.raw_data = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.initializers.push(p);
        name.into()
    }

    /// A scalar float initializer (`Clip`'s bounds).
    fn scalar(&mut self, name: &str, v: f32) -> String {
        let mut p = TensorProto::new();
        p.name = name.into();
        p.data_type = DataType::FLOAT as i32;
        p.raw_data = v.to_le_bytes().to_vec();
        self.initializers.push(p);
        name.into()
    }

    /// An int64 vector initializer (`Reshape`'s shape).
    fn constant_i64(&mut self, name: &str, v: &[i64]) -> String {
        let mut p = TensorProto::new();
        p.name = name.into();
        p.dims = vec![v.len() as i64];
        p.data_type = DataType::INT64 as i32;
        p.raw_data = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.initializers.push(p);
        name.into()
    }

    /// The checkpoint variable `name`.
    fn var(&self, name: &str) -> Result<Tensor, RlError> {
        self.vars.get(name).map(|t| t.detach()).ok_or_else(|| {
            RlError::Invalid(format!("ONNX export: the policy has no variable {name}"))
        })
    }

    /// The MLP whose layers are `prefix.<i>.{weight,bias}` on `x`: `Gemm`
    /// (`transB`) per layer, the activation after every layer but the last,
    /// and after the last too when `encoder`.
    fn mlp(&mut self, prefix: &str, x: &str, encoder: bool) -> Result<String, RlError> {
        let layers = (0..)
            .take_while(|i| self.vars.contains_key(&format!("{prefix}.{i}.weight")))
            .count();
        if layers == 0 {
            return Err(RlError::Invalid(format!(
                "ONNX export: the policy has no layers {prefix}.*"
            )));
        }
        let mut h = x.to_string();
        for i in 0..layers {
            let w = self.var(&format!("{prefix}.{i}.weight"))?;
            let b = self.var(&format!("{prefix}.{i}.bias"))?;
            let w = self.constant(&format!("{prefix}.{i}.weight"), &w);
            let b = self.constant(&format!("{prefix}.{i}.bias"), &b);
            h = self.node("Gemm", &[&h, &w, &b], vec![attr_int("transB", 1)]);
            if encoder || i + 1 < layers {
                let op = match self.activation {
                    Activation::Elu => "Elu",
                    Activation::Relu => "Relu",
                    Activation::Tanh => "Tanh",
                };
                h = self.node(op, &[&h], vec![]);
            }
        }
        Ok(h)
    }

    /// ONNX `GRU` over `seq` `[T, batch, in]` with PyTorch's one-layer weights
    /// `prefix.{weight,bias}_{ih,hh}_l0`, from a zero state; the last hidden
    /// state `[batch, hidden]`.
    fn gru(&mut self, prefix: &str, seq: &str, hidden: i64) -> Result<String, RlError> {
        // PyTorch stacks the gates (r, z, n); ONNX (z, r, h)
        let reorder = |t: Tensor| {
            let c = t.chunk(3, 0);
            Tensor::cat(&[&c[1], &c[0], &c[2]], 0)
        };
        let w = reorder(self.var(&format!("{prefix}.weight_ih_l0"))?).unsqueeze(0);
        let r = reorder(self.var(&format!("{prefix}.weight_hh_l0"))?).unsqueeze(0);
        let bi = reorder(self.var(&format!("{prefix}.bias_ih_l0"))?);
        let bh = reorder(self.var(&format!("{prefix}.bias_hh_l0"))?);
        let b = Tensor::cat(&[bi, bh], 0).unsqueeze(0);
        let w = self.constant(&format!("{prefix}.W"), &w);
        let r = self.constant(&format!("{prefix}.R"), &r);
        let b = self.constant(&format!("{prefix}.B"), &b);
        self.next += 1;
        let (y, yh) = (
            format!("{prefix}_gru_y_{}", self.next),
            format!("{prefix}_gru_h_{}", self.next),
        );
        self.nodes.push(node(
            "GRU",
            &[seq, &w, &r, &b],
            &[&y, &yh],
            vec![
                attr_int("hidden_size", hidden),
                attr_int("linear_before_reset", 1),
            ],
        ));
        let axes = self.constant_i64(&format!("{prefix}_squeeze_axes"), &[0]);
        Ok(self.node("Squeeze", &[&yh, &axes], vec![]))
    }
}

fn node(op: &str, inputs: &[&str], outputs: &[&str], attrs: Vec<AttributeProto>) -> NodeProto {
    let mut n = NodeProto::new();
    n.op_type = op.into();
    n.name = outputs.first().map(|o| o.to_string()).unwrap_or_default();
    n.input = inputs.iter().map(|s| s.to_string()).collect();
    n.output = outputs.iter().map(|s| s.to_string()).collect();
    n.attribute = attrs;
    n
}

fn attr_int(name: &str, v: i64) -> AttributeProto {
    let mut a = AttributeProto::new();
    a.name = name.into();
    a.type_ = AttributeType::INT.into();
    a.i = v;
    a
}

fn attr_ints(name: &str, v: &[i64]) -> AttributeProto {
    let mut a = AttributeProto::new();
    a.name = name.into();
    a.type_ = AttributeType::INTS.into();
    a.ints = v.to_vec();
    a
}

#[derive(Clone, Copy)]
enum Dim {
    Value(i64),
    Param(&'static str),
}

/// A float tensor input or output of shape `dims`.
fn value_info(name: &str, dims: &[Dim]) -> ValueInfoProto {
    let mut shape = TensorShapeProto::new();
    shape.dim = dims
        .iter()
        .map(|d| {
            let mut x = tensor_shape_proto::Dimension::new();
            x.value = Some(match *d {
                Dim::Value(v) => tensor_shape_proto::dimension::Value::DimValue(v),
                Dim::Param(p) => tensor_shape_proto::dimension::Value::DimParam(p.into()),
            });
            x
        })
        .collect();
    let mut tt = type_proto::Tensor::new();
    tt.elem_type = DataType::FLOAT as i32;
    tt.shape = Some(shape).into();
    let mut ty = TypeProto::new();
    ty.value = Some(type_proto::Value::TensorType(tt));
    let mut v = ValueInfoProto::new();
    v.name = name.into();
    v.type_ = Some(ty).into();
    v
}

/// File name of a bundle's reference inputs and outputs (`write_reference`).
pub const REFERENCE_FILE: &str = "policy_reference.npz";

/// What [`write_reference`] wrote: how many rows of each kind.
#[derive(Debug, Clone, Serialize)]
pub struct ReferenceInfo {
    pub path: String,
    pub rollout_rows: usize,
    pub random_rows: usize,
}

/// Write reference inputs and the TorchScript module's actions on them into an
/// `.npz` at `out`, for checking any runtime that runs the ONNX graph
/// (`scripts/check_onnx_python.py`, a robot's controller): arrays
/// `{rollout,random}_{obs,history,scan}` (raw inputs as the graph takes them)
/// and `{rollout,random}_action` (what `torchscript`, the same actor's
/// TorchScript file, computes on them). The rollout rows are every 6th control
/// step of the policy walking 60 steps on the plane of its own env; the random
/// rows are 8 draws of N(0, 1.5²).
pub fn write_reference(
    ck: &Checkpoint,
    torchscript: &Path,
    out: &Path,
) -> Result<ReferenceInfo, RlError> {
    use crate::rl::VecTask;
    let (cfg, mut agent) = super::export::checkpoint_agent(ck)?;
    let mut env_cfg = cfg.env.clone();
    env_cfg.n_envs = 1;
    env_cfg.threads = 1;
    env_cfg.terrain.mode = crate::env::config::TerrainMode::Plane;
    let mut env = crate::env::VecEnv::new(&env_cfg)?;
    agent.set_frozen(true);
    agent.reset_history(&env);
    let d = agent.dims();
    let k = agent.policy.history_len();
    let (mut obs, mut hist, mut scan) = (Vec::new(), Vec::new(), Vec::new());
    for step in 0..60 {
        // the inputs of this step: the current state, the K before it
        if step % 6 == 5 {
            obs.extend_from_slice(env.obs());
            hist.extend_from_slice(agent.history());
            scan.extend_from_slice(env.scan());
        }
        agent.step_mean(&mut env);
    }
    let rows = obs.len() / d.obs;
    let module = tch::CModule::load(torchscript)?;
    let f = |v: Vec<f32>, shape: &[i64]| Tensor::from_slice(&v).reshape(shape);
    let (n, k64, o, s) = (rows as i64, k as i64, d.obs as i64, d.scan as i64);
    let real = [f(obs, &[n, o]), f(hist, &[n, k64, o]), f(scan, &[n, s])];
    tch::manual_seed(17);
    let opts = (Kind::Float, tch::Device::Cpu);
    let random = [
        Tensor::randn([8, o], opts) * 1.5,
        Tensor::randn([8, k64, o], opts) * 1.5,
        Tensor::randn([8, s], opts) * 1.5,
    ];
    let run = |x: &[Tensor; 3]| tch::no_grad(|| module.forward_ts(x));
    let (real_a, random_a) = (run(&real)?, run(&random)?);
    let mut named: Vec<(String, Tensor)> = Vec::new();
    for (tag, x, a) in [("rollout", real, real_a), ("random", random, random_a)] {
        let [xo, xh, xs] = x;
        named.push((format!("{tag}_obs"), xo));
        named.push((format!("{tag}_history"), xh));
        named.push((format!("{tag}_scan"), xs));
        named.push((format!("{tag}_action"), a));
    }
    Tensor::write_npz(&named, out)?;
    Ok(ReferenceInfo {
        path: out.display().to_string(),
        rollout_rows: rows,
        random_rows: 8,
    })
}
