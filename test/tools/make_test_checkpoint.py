#!/usr/bin/env python3
"""Write a realistic LeRobot ACT checkpoint folder plus float64 reference outputs, for tests.

The two hand-made fixtures in shared/fixtures are tiny (D 64, 96x128 images).  The engine also has
to be right for the shapes real robots use (D 512, 480x640 images, 302 encoder tokens), for both
checkpoint layouts and for the less common options (pre-norm, GELU, several cameras of different
sizes, environment state, resnet34/50, dilation, every normalisation mode, temporal ensembling).
Storing such checkpoints in git is out of the question (the default model alone is 200 MB), so this
script generates them deterministically at test time:

    make_test_checkpoint.py --preset default-480x640 --out build/test/data/default-480x640
    make_test_checkpoint.py --list

Each folder mimics a real LeRobot checkpoint exactly (config.json field order of its layout,
processor pipeline files with statistics of every dataset feature, VAE training weights) and holds a
`reference.safetensors` named like the fixtures' one.  The reference outputs come from the float64
forward pass of shared/tools/act_reference/spec_forward.py (imported, not copied), run on the files
as written, so they test the files and not this script's in-memory state.  The few things
spec_forward does not cover (dilated resnet stages, QUANTILES/QUANTILE10 normalisation, temporal
ensembling) are added here from the text of shared/spec/act-inference.md.

Weights are random but of realistic scale: LeRobot's initialisation, every constant-initialised
tensor randomised, and FrozenBatchNorm statistics calibrated on the activations they actually see,
so that features stay O(1-10) through the whole ResNet, as in a trained network.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import shutil
import struct
import sys
import time
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

REPO_ROOT = Path(__file__).resolve().parents[2]
BN_EPS = 1e-5  # FrozenBatchNorm2d
NORM_EPS = 1e-8  # processor "eps" (current layout); hard-coded in the legacy layout
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
BOOKKEEPING_FEATURES = ("timestamp", "frame_index", "episode_index", "index", "task_index")
QUANTILE_STATS = {"q01": 0.01, "q10": 0.10, "q50": 0.50, "q90": 0.90, "q99": 0.99}
# The statistics each [-1, 1] range mode maps to -1 and +1 (spec §3.1).
RANGE_BOUNDS = {"MIN_MAX": ("min", "max"), "QUANTILES": ("q01", "q99"),
                "QUANTILE10": ("q10", "q90")}
QUANTILE_MODES = ("QUANTILES", "QUANTILE10")  # current layout only; spec_forward lacks them
# The float32 self-check must agree with the float64 reference to this (relative to the tensor's
# magnitude).  Seen: 1e-6 (actions) to 4e-5 (resnet50 layer4); a wrong file or order gives O(1).
VERIFY_TOLERANCE = 5e-4
STATE_KEY = "observation.state"
ENV_KEY = "observation.environment_state"
ACTION_KEY = "action"

# spec_forward and its act_harness.stio, imported from the shared folder by load_shared_tools().
spec_forward = None
stio = None
_spec_backbone = None  # spec_forward.backbone, before run_forward swaps in dilated_backbone


# ----------------------------------------------------------------------------------------- presets
@dataclass
class Camera:
    key: str
    height: int
    width: int


@dataclass
class Preset:
    """Everything that distinguishes one generated checkpoint from another."""

    description: str
    layout: str  # "current" (processor files) or "legacy" (normalisation buffers in the model)
    cameras: list[Camera]
    state_dim: int
    action_dim: int
    env_dim: int = 0
    # Key order of config.json's input_features; None = state, env, then the cameras.
    feature_order: list[str] | None = None
    vision_backbone: str = "resnet18"
    dilation: bool | int = False  # written verbatim to config.json (LeRobot writes false or 0)
    dim_model: int = 512
    n_heads: int = 8
    dim_feedforward: int = 3200
    n_encoder_layers: int = 4
    n_decoder_layers: int = 1
    chunk_size: int = 100
    n_action_steps: int = 100
    pre_norm: bool = False
    feedforward_activation: str = "relu"
    use_vae: bool = True
    latent_dim: int = 32
    normalization_mapping: dict[str, str] = field(
        default_factory=lambda: {"VISUAL": "MEAN_STD", "STATE": "MEAN_STD", "ACTION": "MEAN_STD"})
    temporal_ensemble_coeff: float | None = None
    constant_state_dims: list[int] = field(default_factory=list)  # dataset min == max there
    imagenet_image_stats: bool = False  # LeRobot's use_imagenet_stats (real checkpoints' default)
    samples: int = 3


# The transformer of the small presets (the shared fixtures' act-tiny size).
SMALL_TRANSFORMER = {"dim_model": 64, "n_heads": 4, "dim_feedforward": 128, "n_encoder_layers": 2,
                     "n_decoder_layers": 1, "chunk_size": 10}

PRESETS: dict[str, Preset] = {
    "default-480x640": Preset(
        description="LeRobot's default ACT (resnet18, D 512, 4+1 layers, chunk 100) on one "
                    "480x640 camera, 6-dim state/action, MEAN_STD with ImageNet image stats",
        layout="current",
        cameras=[Camera("observation.images.front", 480, 640)],
        state_dim=6, action_dim=6, imagenet_image_stats=True, samples=2),
    "default-360x640-legacy": Preset(
        description="default architecture, 360x640 camera, 2-dim state/action, legacy layout; the "
                    "camera name contains '_' (legacy buffer names are ambiguous to reverse)",
        layout="legacy",
        cameras=[Camera("observation.images.cam_high", 360, 640)],
        state_dim=2, action_dim=2, imagenet_image_stats=True, samples=2),
    "multicam-prenorm-gelu": Preset(
        description="two cameras of different sizes in non-alphabetical order with the state "
                    "between them, env state (ENV not in the mapping => identity), pre-norm, GELU, "
                    "MIN_MAX state/action with one constant state dimension (min == max)",
        layout="current",
        cameras=[Camera("observation.images.wrist", 64, 96),
                 Camera("observation.images.top", 96, 128)],
        feature_order=["observation.images.wrist", STATE_KEY, "observation.images.top", ENV_KEY],
        state_dim=5, action_dim=4, env_dim=3, constant_state_dims=[2],
        dim_model=128, n_heads=8, dim_feedforward=256, n_encoder_layers=3, n_decoder_layers=2,
        chunk_size=20, n_action_steps=5, pre_norm=True, feedforward_activation="gelu",
        normalization_mapping={"VISUAL": "MEAN_STD", "STATE": "MIN_MAX", "ACTION": "MIN_MAX"}),
    "minmax-legacy-env": Preset(
        description="legacy layout, MIN_MAX image/state/action, env state MEAN_STD, temporal "
                    "ensembling (coeff 0.01, n_action_steps 1)",
        layout="legacy",
        cameras=[Camera("observation.images.front", 80, 112)],
        state_dim=4, action_dim=3, env_dim=4,
        dim_model=96, n_heads=4, dim_feedforward=192, n_encoder_layers=2, n_decoder_layers=1,
        chunk_size=15, n_action_steps=1, temporal_ensemble_coeff=0.01,
        normalization_mapping={"VISUAL": "MIN_MAX", "STATE": "MIN_MAX", "ENV": "MEAN_STD",
                               "ACTION": "MIN_MAX"},
        samples=4),
    "resnet34-novae": Preset(
        description="resnet34 backbone, use_vae false (no vae_* tensors), "
                    "replace_final_stride_with_dilation written as 0",
        layout="current",
        cameras=[Camera("observation.images.front", 64, 96)],
        state_dim=3, action_dim=3, vision_backbone="resnet34", dilation=0, use_vae=False,
        **SMALL_TRANSFORMER, n_action_steps=3),
    "resnet50-dilation": Preset(
        description="resnet50 (Bottleneck, 2048-channel feature map) with "
                    "replace_final_stride_with_dilation true: layer4 dilated, feature map H/16",
        layout="current",
        cameras=[Camera("observation.images.front", 64, 64)],
        state_dim=2, action_dim=2, vision_backbone="resnet50", dilation=True,
        **SMALL_TRANSFORMER, n_action_steps=10),
    "quantiles-identity": Preset(
        description="IDENTITY images (raw [0,1] into the backbone), QUANTILES state (q01/q99), "
                    "QUANTILE10 action (q10/q90)",
        layout="current",
        cameras=[Camera("observation.images.front", 64, 96)],
        state_dim=3, action_dim=3,
        **SMALL_TRANSFORMER, n_action_steps=10,
        normalization_mapping={"VISUAL": "IDENTITY", "STATE": "QUANTILES",
                               "ACTION": "QUANTILE10"}),
}


def preset_from_json(text: str) -> Preset:
    """Inverse of json.dumps(asdict(preset)), as stored in reference.safetensors' metadata."""
    fields = json.loads(text)
    fields["cameras"] = [Camera(**c) for c in fields["cameras"]]
    return Preset(**fields)


def input_features(p: Preset) -> dict[str, dict]:
    """config.json's input_features, in the preset's key order (the camera order matters)."""
    feats = {cam.key: {"type": "VISUAL", "shape": [3, cam.height, cam.width]} for cam in p.cameras}
    feats[STATE_KEY] = {"type": "STATE", "shape": [p.state_dim]}
    if p.env_dim:
        feats[ENV_KEY] = {"type": "ENV", "shape": [p.env_dim]}
    order = p.feature_order or [STATE_KEY] + ([ENV_KEY] if p.env_dim else []) + [
        cam.key for cam in p.cameras]
    assert sorted(order) == sorted(feats), "feature_order must list every input feature once"
    return {key: feats[key] for key in order}


def output_features(p: Preset) -> dict[str, dict]:
    return {ACTION_KEY: {"type": "ACTION", "shape": [p.action_dim]}}


# ------------------------------------------------------------------------------------- config.json
def build_config(p: Preset) -> dict:
    """config.json as LeRobot writes it, with the field order of the preset's layout (spec §9)."""
    weights_name = "ResNet%s_Weights.IMAGENET1K_V1" % p.vision_backbone[len("resnet"):]
    head = {"type": "act", "n_obs_steps": 1}
    features = {"input_features": input_features(p), "output_features": output_features(p)}
    mapping = {"normalization_mapping": dict(p.normalization_mapping)}
    hub = {"device": "cpu", "use_amp": False}
    if p.layout == "current":
        hub["use_peft"] = False
    hub.update({"push_to_hub": True, "repo_id": None, "private": None, "tags": None,
                "license": None})
    if p.layout == "current":
        hub.update({"pretrained_path": None, "pretrained_revision": None})
    chunking = {"chunk_size": p.chunk_size, "n_action_steps": p.n_action_steps}
    model = {
        "vision_backbone": p.vision_backbone,
        "pretrained_backbone_weights": weights_name,
        "replace_final_stride_with_dilation": p.dilation,
        "pre_norm": p.pre_norm,
        "dim_model": p.dim_model,
        "n_heads": p.n_heads,
        "dim_feedforward": p.dim_feedforward,
        "feedforward_activation": p.feedforward_activation,
        "n_encoder_layers": p.n_encoder_layers,
        "n_decoder_layers": p.n_decoder_layers,
        "use_vae": p.use_vae,
        "latent_dim": p.latent_dim,
        "n_vae_encoder_layers": 4,
        "temporal_ensemble_coeff": p.temporal_ensemble_coeff,
        "dropout": 0.1,
        "kl_weight": 10.0,
        "optimizer_lr": 1e-05,
        "optimizer_weight_decay": 0.0001,
        "optimizer_lr_backbone": 1e-05,
    }
    if p.layout == "current":
        return {**head, **features, **hub, **chunking, **mapping, **model}
    return {**head, **mapping, **features, **hub, **chunking, **model}


# ----------------------------------------------------------------------------------------- weights
def _f32(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32)


class WeightMaker:
    """LeRobot/torch initialisation schemes, plus random values for constant-initialised tensors.

    Constants (LayerNorm 1/0, attention biases 0, BatchNorm 1/0) are randomised on purpose: an
    engine that forgets to apply one of them would otherwise still pass.
    """

    def __init__(self, rng: np.random.Generator):
        self.rng = rng
        self.w: dict[str, np.ndarray] = {}

    def uniform(self, name, bound, shape):
        self.w[name] = _f32(self.rng.uniform(-bound, bound, shape))

    def normal(self, name, std, shape):
        self.w[name] = _f32(self.rng.normal(0.0, std, shape))

    def xavier(self, name, shape):
        fan_out, fan_in = shape[0], int(np.prod(shape[1:]))
        self.uniform(name, math.sqrt(6.0 / (fan_in + fan_out)), shape)

    def linear(self, name, n_out, n_in):
        """nn.Linear init: kaiming_uniform(a=sqrt(5)) = U(+-1/sqrt(fan_in)); the bias too."""
        self.uniform(name + ".weight", 1.0 / math.sqrt(n_in), (n_out, n_in))
        self.uniform(name + ".bias", 1.0 / math.sqrt(n_in), (n_out,))

    def layer_norm(self, name, dim):
        self.w[name + ".weight"] = _f32(self.rng.uniform(0.75, 1.25, dim))
        self.normal(name + ".bias", 0.1, (dim,))

    def attention(self, name, dim, xavier_out):
        """nn.MultiheadAttention: xavier in_proj, zero biases (randomised here).

        out_proj is a Linear (kaiming-uniform) unless ACT's _reset_parameters re-inits it with
        xavier, which it does for the encoder and decoder but not the VAE encoder."""
        self.xavier(name + ".in_proj_weight", (3 * dim, dim))
        self.normal(name + ".in_proj_bias", 0.05, (3 * dim,))
        if xavier_out:
            self.xavier(name + ".out_proj.weight", (dim, dim))
        else:
            self.uniform(name + ".out_proj.weight", 1.0 / math.sqrt(dim), (dim, dim))
        self.normal(name + ".out_proj.bias", 0.05, (dim,))

    def ffn(self, name, dim, dim_ff, xavier):
        self.linear(name + ".linear1", dim_ff, dim)
        self.linear(name + ".linear2", dim, dim_ff)
        if xavier:  # ACT._reset_parameters: xavier_uniform_ on every >1-D encoder/decoder tensor
            self.xavier(name + ".linear1.weight", (dim_ff, dim))
            self.xavier(name + ".linear2.weight", (dim, dim_ff))


def make_transformer_weights(p: Preset, mk: WeightMaker) -> None:
    """Every non-backbone `model.*` tensor of LeRobot's ACT (spec §7, appendix A)."""
    D, Fd, m = p.dim_model, p.dim_feedforward, "model."
    if p.use_vae:
        for i in range(4):  # n_vae_encoder_layers
            q = f"{m}vae_encoder.layers.{i}"
            mk.attention(q + ".self_attn", D, xavier_out=False)
            mk.ffn(q, D, Fd, xavier=False)
            mk.layer_norm(q + ".norm1", D)
            mk.layer_norm(q + ".norm2", D)
        if p.pre_norm:
            mk.layer_norm(m + "vae_encoder.norm", D)
        mk.normal(m + "vae_encoder_cls_embed.weight", 1.0, (1, D))  # nn.Embedding: N(0, 1)
        mk.linear(m + "vae_encoder_robot_state_input_proj", D, p.state_dim)
        mk.linear(m + "vae_encoder_action_input_proj", D, p.action_dim)
        mk.linear(m + "vae_encoder_latent_output_proj", 2 * p.latent_dim, D)
        mk.w[m + "vae_encoder_pos_enc"] = _f32(sinusoid_table(1 + p.chunk_size + 1, D)[None])
    for i in range(p.n_encoder_layers):
        q = f"{m}encoder.layers.{i}"
        mk.attention(q + ".self_attn", D, xavier_out=True)
        mk.ffn(q, D, Fd, xavier=True)
        mk.layer_norm(q + ".norm1", D)
        mk.layer_norm(q + ".norm2", D)
    if p.pre_norm:
        mk.layer_norm(m + "encoder.norm", D)
    for i in range(p.n_decoder_layers):
        q = f"{m}decoder.layers.{i}"
        mk.attention(q + ".self_attn", D, xavier_out=True)
        mk.attention(q + ".multihead_attn", D, xavier_out=True)
        mk.ffn(q, D, Fd, xavier=True)
        for j in (1, 2, 3):
            mk.layer_norm(f"{q}.norm{j}", D)
    mk.layer_norm(m + "decoder.norm", D)
    mk.linear(m + "encoder_robot_state_input_proj", D, p.state_dim)
    if p.env_dim:
        mk.linear(m + "encoder_env_state_input_proj", D, p.env_dim)
    mk.linear(m + "encoder_latent_input_proj", D, p.latent_dim)
    c_fm = feature_map_channels(p.vision_backbone)
    mk.uniform(m + "encoder_img_feat_input_proj.weight", 1 / math.sqrt(c_fm), (D, c_fm, 1, 1))
    mk.uniform(m + "encoder_img_feat_input_proj.bias", 1 / math.sqrt(c_fm), (D,))
    n_1d = 2 + (1 if p.env_dim else 0)  # latent, state, env
    mk.normal(m + "encoder_1d_feature_pos_embed.weight", 1.0, (n_1d, D))
    mk.normal(m + "decoder_pos_embed.weight", 1.0, (p.chunk_size, D))
    mk.linear(m + "action_head", p.action_dim, D)


def sinusoid_table(n_positions: int, dim: int) -> np.ndarray:
    """LeRobot's create_sinusoidal_pos_embedding (the VAE encoder's fixed position buffer)."""
    pos = np.arange(n_positions)[:, None]
    j = np.arange(dim)[None, :]
    table = pos / np.power(10000, 2 * (j // 2) / dim)
    table[:, 0::2] = np.sin(table[:, 0::2])
    table[:, 1::2] = np.cos(table[:, 1::2])
    return table


# ---------------------------------------------------------------------------------------- backbone
RESNET_BLOCKS = {"resnet18": ("basic", [2, 2, 2, 2]), "resnet34": ("basic", [3, 4, 6, 3]),
                 "resnet50": ("bottleneck", [3, 4, 6, 3]),
                 "resnet101": ("bottleneck", [3, 4, 23, 3]),
                 "resnet152": ("bottleneck", [3, 8, 36, 3])}


def feature_map_channels(backbone: str) -> int:
    return 512 if RESNET_BLOCKS[backbone][0] == "basic" else 2048


def resnet_convs(backbone: str, dilate: bool):
    """The torchvision ResNet as a list of conv+BN steps, which is all calibration needs.

    Yields ("conv", conv_name, bn_name, cin, cout, k, stride, pad, dilation, relu) and
    ("block_start"/"block_end", prefix) markers around each residual block; the block's
    downsample conv (if any) is listed first and applies to the block input.
    """
    kind, counts = RESNET_BLOCKS[backbone]
    p = "model.backbone."
    yield ("conv", p + "conv1", p + "bn1", 3, 64, 7, 2, 3, 1, True)
    yield ("maxpool",)
    cin, expansion = 64, (1 if kind == "basic" else 4)
    for li, n in enumerate(counts, start=1):
        width = 64 * 2 ** (li - 1)
        cout = width * expansion
        for bi in range(n):
            q = f"{p}layer{li}.{bi}."
            stride = 2 if (bi == 0 and li > 1) else 1
            dil = 1
            if dilate and li == 4:  # torchvision replace_stride_with_dilation (spec §4.3)
                stride, dil = 1, (1 if bi == 0 else 2)
            yield ("block_start", q)
            if bi == 0 and (stride != 1 or cin != cout):
                yield ("downsample", q + "downsample.0", q + "downsample.1", cin, cout, 1, stride,
                       0, 1, False)
            if kind == "basic":
                yield ("conv", q + "conv1", q + "bn1", cin, width, 3, stride, 1, 1, True)
                yield ("conv", q + "conv2", q + "bn2", width, width, 3, 1, 1, 1, False)
            else:
                yield ("conv", q + "conv1", q + "bn1", cin, width, 1, 1, 0, 1, True)
                yield ("conv", q + "conv2", q + "bn2", width, width, 3, stride, dil, dil, True)
                yield ("conv", q + "conv3", q + "bn3", width, cout, 1, 1, 0, 1, False)
            yield ("block_end", q)
            cin = cout


def make_backbone_weights(p: Preset, mk: WeightMaker, calib_images: list[torch.Tensor]) -> dict:
    """Kaiming conv weights + FrozenBatchNorm buffers calibrated on the activations they see.

    A random network with identity BNs explodes or dies within a few blocks; a trained one keeps
    every BN input close to its running statistics.  So each BN's running mean/var are set from the
    real per-channel statistics of its input (the conv output) over `calib_images` (one batch per
    camera size, already normalised as the policy would), then jittered so that BN folding still
    changes the numbers; weight ~ U(0.5, 1.5), bias ~ N(0, 0.1).  Returns per-stage RMS values of
    the calibration activations (printed as a scale check).
    """
    rng = mk.rng
    xs = [x.float() for x in calib_images]
    block_in: list[torch.Tensor] = []
    shortcut: list[torch.Tensor] | None = None
    scale = {}
    for step in resnet_convs(p.vision_backbone, bool(p.dilation)):
        kind = step[0]
        if kind == "maxpool":
            xs = [F.max_pool2d(x, 3, 2, 1) for x in xs]
            continue
        if kind == "block_start":
            block_in, shortcut = xs, None
            continue
        if kind == "block_end":
            xs = [F.relu(y + s) for y, s in zip(xs, shortcut if shortcut else block_in)]
            scale[step[1].split(".")[2]] = _rms(xs)  # last block of "layerN" wins
            continue
        _, conv, bn, cin, cout, k, stride, pad, dil, relu = step
        mk.normal(conv + ".weight", math.sqrt(2.0 / (cout * k * k)), (cout, cin, k, k))
        weight = torch.from_numpy(mk.w[conv + ".weight"])
        src = block_in if kind == "downsample" else xs
        zs = [F.conv2d(x, weight, stride=stride, padding=pad, dilation=dil) for x in src]
        flat = torch.cat([z.transpose(0, 1).reshape(cout, -1) for z in zs], dim=1).double()
        mean, std = flat.mean(1).numpy(), flat.std(1, unbiased=False).numpy()
        mk.w[bn + ".running_mean"] = _f32(mean + 0.1 * std * rng.standard_normal(cout))
        mk.w[bn + ".running_var"] = _f32(std ** 2 * rng.uniform(0.8, 1.25, cout))
        mk.w[bn + ".weight"] = _f32(rng.uniform(0.5, 1.5, cout))
        mk.normal(bn + ".bias", 0.1, (cout,))
        k_bn = mk.w[bn + ".weight"] / np.sqrt(mk.w[bn + ".running_var"] + BN_EPS)
        b_bn = mk.w[bn + ".bias"] - mk.w[bn + ".running_mean"] * k_bn
        k_t, b_t = torch.from_numpy(k_bn)[:, None, None], torch.from_numpy(b_bn)[:, None, None]
        ys = [z * k_t + b_t for z in zs]
        if kind == "downsample":
            shortcut = ys
        else:
            xs = [F.relu(y) for y in ys] if relu else ys
        if conv == "model.backbone.conv1":
            scale["stem"] = _rms(xs)
    return scale


def _rms(tensors: list[torch.Tensor]) -> float:
    return float(torch.sqrt(torch.mean(torch.cat([t.flatten() for t in tensors]) ** 2)))


# -------------------------------------------------------------------------------------------- data
def synth_image(rng: np.random.Generator, height: int, width: int) -> np.ndarray:
    """A smooth-ish RGB scene (uint8 HxWx3): colour gradients, a few flat shapes, sensor noise.

    Pure noise would make every conv output look alike; real frames have large smooth regions
    and sharp object edges, which is what this imitates.
    """
    gh, gw = int(rng.integers(2, 6)), int(rng.integers(2, 7))
    grid = torch.from_numpy(rng.uniform(0.1, 0.9, (1, 3, gh, gw)))
    img = F.interpolate(grid, size=(height, width), mode="bicubic", align_corners=True)[0].numpy()
    yy, xx = np.mgrid[0:height, 0:width]
    for _ in range(int(rng.integers(3, 8))):
        colour = rng.uniform(0.0, 1.0, (3, 1))
        cy, cx = rng.uniform(0, height), rng.uniform(0, width)
        ry, rx = rng.uniform(0.05, 0.3) * height, rng.uniform(0.05, 0.3) * width
        if rng.random() < 0.5:
            mask = ((yy - cy) / ry) ** 2 + ((xx - cx) / rx) ** 2 <= 1.0
        else:
            mask = (np.abs(yy - cy) <= ry) & (np.abs(xx - cx) <= rx)
        img[:, mask] = 0.8 * colour + 0.2 * img[:, mask]
    img += rng.normal(0.0, 0.015, img.shape)
    return np.clip(np.round(img * 255.0), 0, 255).astype(np.uint8).transpose(1, 2, 0).copy()


def synth_trajectories(rng, lengths, fps, dim, offset, amplitude) -> np.ndarray:
    """Joint-like signals: two sinusoids per dimension and episode, a per-episode offset, noise."""
    off = rng.uniform(-offset, offset, dim)
    amp = rng.uniform(0.2 * amplitude, amplitude, dim)
    parts = []
    for n in lengths:
        t = np.arange(n)[:, None] / fps
        f1, f2 = rng.uniform(0.05, 0.3, dim), rng.uniform(0.4, 1.2, dim)
        ph1, ph2 = rng.uniform(0, 2 * np.pi, dim), rng.uniform(0, 2 * np.pi, dim)
        x = (off + 0.3 * amp * rng.standard_normal(dim) + amp * np.sin(2 * np.pi * f1 * t + ph1)
             + 0.25 * amp * np.sin(2 * np.pi * f2 * t + ph2)
             + 0.02 * amp * rng.standard_normal((n, dim)))
        parts.append(x)
    return _f32(np.concatenate(parts))


def feature_stats(x: np.ndarray) -> dict[str, np.ndarray]:
    """LeRobot dataset statistics of a (frames, dim) array: min/max/mean/std/count/quantiles."""
    x64 = x.astype(np.float64)
    stats = {"min": x64.min(0), "max": x64.max(0), "mean": x64.mean(0), "std": x64.std(0),
             "count": np.array([x.shape[0]])}
    for name, q in QUANTILE_STATS.items():
        stats[name] = np.quantile(x64, q, axis=0)
    return {k: _f32(v) for k, v in stats.items()}


def make_dataset(p: Preset, rng: np.random.Generator):
    """A synthetic LeRobot dataset: per-frame vectors, stats of every feature, sample indices.

    Inputs are taken from the same frames the statistics describe, so normalised inputs look like
    training data (and a constant state dimension is fed exactly its constant).
    """
    lengths, fps = rng.integers(150, 400, size=24), 30  # 24 episodes of 5-13 s at 30 fps
    frames = {}
    state = synth_trajectories(rng, lengths, fps, p.state_dim, offset=60.0, amplitude=50.0)
    for d in p.constant_state_dims:
        state[:, d] = np.float32(round(float(state[0, d]), 1))
    frames[STATE_KEY] = state
    if p.action_dim == p.state_dim:  # the commanded position leads the measured one
        ends = np.cumsum(lengths) - 1
        lead = np.minimum(np.arange(len(state)) + 5, np.repeat(ends, lengths))
        action = state[lead] + _f32(rng.normal(0.0, 0.5, state.shape))
    else:
        action = synth_trajectories(rng, lengths, fps, p.action_dim, offset=60.0, amplitude=50.0)
    frames[ACTION_KEY] = _f32(action)
    if p.env_dim:
        frames[ENV_KEY] = synth_trajectories(rng, lengths, fps, p.env_dim, offset=0.3,
                                             amplitude=0.15)
    frame_index = np.concatenate([np.arange(n) for n in lengths])
    bookkeeping = {
        "timestamp": frame_index / fps,
        "frame_index": frame_index,
        "episode_index": np.repeat(np.arange(len(lengths)), lengths),
        "index": np.arange(len(frame_index)),
        "task_index": np.zeros(len(frame_index)),
    }
    stats = {key: feature_stats(x) for key, x in frames.items()}
    for key in BOOKKEEPING_FEATURES:
        stats[key] = feature_stats(_f32(bookkeeping[key])[:, None])
    for cam in p.cameras:
        stats[cam.key] = image_stats(p, rng, cam)
    sample_idx = rng.choice(len(state), size=p.samples, replace=False)
    return stats, {k: v[sample_idx] for k, v in frames.items()}


def image_stats(p: Preset, rng, cam: Camera) -> dict[str, np.ndarray]:
    """Per-channel stats (3,1,1) of a few synthetic frames; ImageNet mean/std if the preset asks."""
    n = 4
    pixels = np.stack([synth_image(rng, cam.height, cam.width) for _ in range(n)])
    stats = feature_stats(pixels.reshape(-1, 3).astype(np.float32) / 255.0)
    stats["count"] = _f32([n])
    if p.imagenet_image_stats:
        stats["mean"], stats["std"] = _f32(IMAGENET_MEAN), _f32(IMAGENET_STD)
    return {k: (v if k == "count" else v.reshape(3, 1, 1)) for k, v in stats.items()}


def normalize_for_calibration(x: np.ndarray, mode: str, st: dict) -> np.ndarray:
    """Image normalisation (spec §3.1) for the BN calibration images, before any file exists.

    Only needs to be close: the reference itself normalises with spec_forward on the files.
    """
    if mode == "MEAN_STD":
        return (x - st["mean"]) / (st["std"] + NORM_EPS)
    if mode not in RANGE_BOUNDS:
        return x
    lo, hi = (st[name] for name in RANGE_BOUNDS[mode])
    return 2 * (x - lo) / np.maximum(hi - lo, NORM_EPS) - 1


# ------------------------------------------------------------------------------------------- files
def write_json(path: Path, obj, indent: int) -> None:
    path.write_text(json.dumps(obj, indent=indent))  # LeRobot writes no trailing newline


def write_png(path: Path, rgb: np.ndarray) -> None:
    """8-bit RGB PNG without PIL (filter 0 on every row)."""
    def chunk(tag: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + tag + data
                + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF))
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[r].tobytes() for r in range(h))
    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)  # 8-bit RGB, no interlace
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
                     + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))


def read_png(path: Path) -> np.ndarray:
    """Inverse of write_png (only what write_png produces), for the self-check."""
    data = path.read_bytes()
    pos, idat, w, h = 8, b"", 0, 0
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        tag, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        if tag == b"IHDR":
            w, h = struct.unpack(">II", body[:8])
        elif tag == b"IDAT":
            idat += body
        pos += 12 + n
    rows = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(h, 1 + 3 * w)
    assert not rows[:, 0].any(), "unexpected PNG filter"
    return rows[:, 1:].reshape(h, w, 3)


def processor_step_config(p: Preset, features: dict) -> dict:
    return {"eps": NORM_EPS, "features": features, "norm_map": dict(p.normalization_mapping)}


def write_current_layout(p: Preset, out: Path, stats: dict) -> None:
    """Processor pipeline JSONs + state files (spec §10.1).

    Both state files hold the whole dataset stats dictionary; the normaliser reshapes 1-D stats of
    every VISUAL feature in its features (so image `count` is (1,1,1) there, (1,) in the other).
    """
    pre_file = "policy_preprocessor_step_3_normalizer_processor.safetensors"
    post_file = "policy_postprocessor_step_0_unnormalizer_processor.safetensors"
    device = {"registry_name": "device_processor", "config": {"device": "cpu", "float_dtype": None}}
    all_features = {**input_features(p), **output_features(p)}
    pre = {"name": "policy_preprocessor", "steps": [
        {"registry_name": "rename_observations_processor", "config": {"rename_map": {}}},
        {"registry_name": "to_batch_processor", "config": {}},
        device,
        {"registry_name": "normalizer_processor",
         "config": processor_step_config(p, all_features), "state_file": pre_file}]}
    post = {"name": "policy_postprocessor", "steps": [
        {"registry_name": "unnormalizer_processor",
         "config": processor_step_config(p, output_features(p)), "state_file": post_file},
        device]}
    write_json(out / "policy_preprocessor.json", pre, indent=2)
    write_json(out / "policy_postprocessor.json", post, indent=2)
    flat = {f"{key}.{name}": v for key, st in stats.items() for name, v in st.items()}
    stio.save_file(flat, out / post_file)
    visual = [k for k, v in all_features.items() if v["type"] == "VISUAL"]
    for key in visual:
        name = f"{key}.count"
        flat[name] = flat[name].reshape(-1, 1, 1)
    stio.save_file(flat, out / pre_file)


def legacy_buffers(p: Preset, stats: dict) -> dict[str, np.ndarray]:
    """normalize_inputs / normalize_targets / unnormalize_outputs buffers (spec §3.3, §10.2)."""
    needed = {"MEAN_STD": ("mean", "std"), "MIN_MAX": ("min", "max")}
    out = {}
    groups = [("normalize_inputs", input_features(p)), ("normalize_targets", output_features(p)),
              ("unnormalize_outputs", output_features(p))]
    for module, feats in groups:
        for key, ft in feats.items():
            mode = p.normalization_mapping.get(ft["type"], "IDENTITY")
            if mode == "IDENTITY":
                continue
            if mode not in needed:
                raise ValueError(f"{mode} does not exist in the legacy layout")
            for stat in needed[mode]:
                out[f"{module}.buffer_{key.replace('.', '_')}.{stat}"] = stats[key][stat]
    return out


# --------------------------------------------------------------------------------------- reference
def load_shared_tools(shared: Path) -> None:
    """Import spec_forward (and act_harness.stio) from the shared folder, and extend it."""
    global spec_forward, stio, _spec_backbone
    tool_dir = shared / "tools" / "act_reference"
    if not (tool_dir / "spec_forward.py").is_file():
        sys.exit(f"error: {tool_dir}/spec_forward.py not found (pass --shared PATH)")
    sys.path.insert(0, str(tool_dir))
    import spec_forward as sf  # noqa: E402
    from act_harness import stio as st  # noqa: E402
    spec_forward, stio, _spec_backbone = sf, st, sf.backbone


def make_reference_checkpoint(folder: Path, dtype):
    """spec_forward.Ckpt plus the normalisation modes it lacks (QUANTILES, QUANTILE10; spec §3.1).

    Defined lazily because the base class is only importable once the shared path is known.
    """
    class RefCkpt(spec_forward.Ckpt):
        def _bounds(self, st, mode, visual):
            lo, hi = (st[name].to(self.dt) for name in RANGE_BOUNDS[mode])
            if visual:
                lo, hi = lo.reshape(-1, 1, 1), hi.reshape(-1, 1, 1)
            span = hi - lo
            return lo, torch.where(span == 0, torch.full_like(span, self.eps_in), span)

        def normalize(self, key, x):
            mode, st = self.norm_mode[key], self.in_stats.get(key, {})
            if mode not in QUANTILE_MODES or not st:
                return super().normalize(key, x)
            visual = self.cfg["input_features"][key]["type"] == "VISUAL"
            lo, span = self._bounds(st, mode, visual)
            return 2 * (x - lo) / span - 1

        def unnormalize(self, a):
            mode, st = self.norm_mode[ACTION_KEY], self.out_stats[ACTION_KEY]
            if mode not in QUANTILE_MODES or not st:
                return super().unnormalize(a)
            lo, span = self._bounds(st, mode, visual=False)
            return (a + 1) * span / 2 + lo

    return RefCkpt(folder, dtype)


def _conv_bn(ck, conv, bn, x, stride, pad, dilation):
    """spec_forward.folded_conv with a dilation argument (FrozenBatchNorm folded, spec §4.3)."""
    weight = ck.t(conv + ".weight")
    k = ck.t(bn + ".weight") / torch.sqrt(ck.t(bn + ".running_var") + BN_EPS)
    bias = ck.t(bn + ".bias") - ck.t(bn + ".running_mean") * k
    return F.conv2d(x, weight * k[:, None, None, None], bias, stride=stride, padding=pad,
                    dilation=dilation)


def dilated_backbone(ck, x):
    """spec_forward.backbone for replace_final_stride_with_dilation (spec §4.3), which it lacks.

    layer4 keeps stride 1 (its downsample too); its first block's 3x3 has dilation 1, the later
    blocks' 3x3 convs dilation 2 / padding 2.  Only Bottleneck ResNets allow this.
    """
    kind, counts = RESNET_BLOCKS[ck.cfg["vision_backbone"]]
    if kind != "bottleneck":
        raise ValueError("torchvision refuses dilation in BasicBlock (resnet18/34)")
    p = "model.backbone."
    x = F.relu(_conv_bn(ck, p + "conv1", p + "bn1", x, 2, 3, 1))
    outs = {"stem": x}
    x = F.max_pool2d(x, 3, 2, 1)
    outs["maxpool"] = x
    for li, n in enumerate(counts, start=1):
        for bi in range(n):
            q = f"{p}layer{li}.{bi}."
            stride = 2 if (bi == 0 and li in (2, 3)) else 1
            dil = 2 if (li == 4 and bi > 0) else 1
            identity = x
            if q + "downsample.0.weight" in ck.w:
                identity = _conv_bn(ck, q + "downsample.0", q + "downsample.1", x, stride, 0, 1)
            y = F.relu(_conv_bn(ck, q + "conv1", q + "bn1", x, 1, 0, 1))
            y = F.relu(_conv_bn(ck, q + "conv2", q + "bn2", y, stride, dil, dil))
            y = _conv_bn(ck, q + "conv3", q + "bn3", y, 1, 0, 1)
            x = F.relu(y + identity)
        outs[f"layer{li}"] = x
    return x, outs


def run_forward(ck, images, state, env):
    """spec_forward.forward, with the dilated backbone swapped in when the config asks for it."""
    if ck.cfg.get("replace_final_stride_with_dilation"):
        spec_forward.backbone = dilated_backbone
    try:
        return spec_forward.forward(ck, images, state, env)
    finally:
        spec_forward.backbone = _spec_backbone


def reference_extensions(p: Preset) -> list[str]:
    """What this script adds to spec_forward for the preset (recorded in the reference metadata)."""
    ext = []
    if p.dilation:
        ext.append("dilated layer4 (dilated_backbone)")
    modes = set(p.normalization_mapping.values()) & set(QUANTILE_MODES)
    if modes:
        ext.append("normalisation " + "/".join(sorted(modes)) + " (RefCkpt)")
    if p.temporal_ensemble_coeff is not None:
        ext.append("temporal ensembling (temporal_ensemble)")
    return ext


def temporal_ensemble(chunks: np.ndarray, coeff: float) -> np.ndarray:
    """LeRobot's online temporal ensembling (spec §6) over chunks (N, T, A) in time order.

    Returns the N actions select_action would return, one per step.
    """
    T = chunks.shape[1]
    weights = np.exp(-coeff * np.arange(T))
    cumsum = np.cumsum(weights)
    pending, counts, actions = None, None, []
    for chunk in chunks:
        if pending is None:
            pending, counts = chunk.copy(), np.ones(T, dtype=np.int64)
        else:
            pending = ((pending * cumsum[counts - 1, None] + chunk[:-1] * weights[counts, None])
                       / cumsum[counts, None])
            counts = np.minimum(counts + 1, T)
            pending = np.concatenate([pending, chunk[-1:]])
            counts = np.concatenate([counts, [1]])
        actions.append(pending[0])
        pending, counts = pending[1:], counts[1:]
    return np.stack(actions)


def temporal_ensemble_closed_form(chunks: np.ndarray, coeff: float) -> np.ndarray:
    """sum_i w_i p_i / sum_i w_i over the predictions of each step, oldest first (spec §6)."""
    T = chunks.shape[1]
    out = []
    for step in range(len(chunks)):
        preds = [chunks[i, step - i] for i in range(max(0, step - T + 1), step + 1)]
        w = np.exp(-coeff * np.arange(len(preds)))
        out.append((w[:, None] * np.stack(preds)).sum(0) / w.sum())
    return np.stack(out)


def select_action_references(ck, raw: np.ndarray, norm: np.ndarray) -> dict[str, np.ndarray]:
    """select_action outputs: the action queue of sample 0, or the temporal ensemble of 0..N-1."""
    cfg = ck.cfg
    coeff = cfg["temporal_ensemble_coeff"]
    if coeff is None:
        return {"select_action.queue_sample0": raw[0, :cfg["n_action_steps"]]}
    if ck.layout == "current":  # ensembles normalised actions, un-normalises afterwards
        ens = ck.unnormalize(torch.from_numpy(temporal_ensemble(norm, coeff))).numpy()
    else:  # legacy ensembles the un-normalised actions
        ens = temporal_ensemble(raw, coeff)
    return {"temporal_ensemble.actions": ens}


def compute_reference(folder: Path, inputs: dict, p: Preset, dtype=torch.float64):
    """Run spec_forward on the written folder for every sample (batch 1 each, like LeRobot)."""
    ck = make_reference_checkpoint(folder, dtype)
    cams = [c.key for c in p.cameras]
    raws, norms, sample0 = [], [], {}
    with torch.no_grad():
        for i in range(p.samples):
            images = {c: torch.from_numpy(inputs[f"input.{c}"][i]) for c in cams}
            state = torch.from_numpy(inputs[f"input.{STATE_KEY}"][i])
            env = torch.from_numpy(inputs[f"input.{ENV_KEY}"][i]) if p.env_dim else None
            raw, norm, inter = run_forward(ck, images, state, env)
            raws.append(raw.numpy())
            norms.append(norm.numpy())
            if i == 0:
                sample0 = {f"sample0.{k}": v.numpy() for k, v in inter.items()}
                if p.env_dim:
                    e = ck.normalize(ENV_KEY, env.to(dtype))[None]
                    sample0[f"sample0.model_input.{ENV_KEY}"] = e.numpy()
    raw, norm = np.stack(raws), np.stack(norms)
    return {"output.action": raw, "output.action_normalized": norm, **sample0,
            **select_action_references(ck, raw, norm)}


# -------------------------------------------------------------------------------------- main steps
def preset_rng(seed: int, name: str) -> np.random.Generator:
    return np.random.default_rng([seed, zlib.crc32(name.encode())])


def make_inputs(p: Preset, rng, sample_frames: dict) -> dict[str, np.ndarray]:
    """reference.safetensors input.* tensors: u8 images, /255 float32 NCHW images, raw vectors."""
    inputs = {}
    for cam in p.cameras:
        u8 = np.stack([synth_image(rng, cam.height, cam.width) for _ in range(p.samples)])
        inputs[f"input.{cam.key}.u8_nhwc"] = u8
        # float32 division, as LeRobot converts camera frames (255 -> exactly 1.0)
        chw = torch.from_numpy(u8).permute(0, 3, 1, 2).to(torch.float32) / 255.0
        inputs[f"input.{cam.key}"] = chw.contiguous().numpy()
    inputs[f"input.{STATE_KEY}"] = sample_frames[STATE_KEY]
    if p.env_dim:
        inputs[f"input.{ENV_KEY}"] = sample_frames[ENV_KEY]
    return inputs


def calibration_batches(p: Preset, rng, stats: dict) -> list[torch.Tensor]:
    """Fresh images per camera, normalised as the policy would see them.

    A couple of images suffice for large frames, but a 64x64 frame has only 4 layer4 positions:
    statistics from so few values fit the calibration images and not the next image, and the
    mismatch compounds block after block.  So use enough images for >= 256 layer4 positions.
    """
    mode = p.normalization_mapping.get("VISUAL", "IDENTITY")
    stride = 16 if p.dilation else 32
    batches = []
    for cam in p.cameras:
        positions = math.ceil(cam.height / stride) * math.ceil(cam.width / stride)
        n = min(32, max(2, math.ceil(256 / positions)))
        u8 = np.stack([synth_image(rng, cam.height, cam.width) for _ in range(n)])
        x = u8.transpose(0, 3, 1, 2).astype(np.float32) / 255.0
        batches.append(torch.from_numpy(_f32(normalize_for_calibration(x, mode, stats[cam.key]))))
    return batches


SCALE_REPORT = [f"sample0.cam0.backbone.{s}" for s in ("stem", "layer1", "layer2", "layer3",
                                                       "layer4")] + [
    "sample0.encoder_out", "sample0.decoder_out", "output.action_normalized", "output.action"]


def magnitudes(arrays: dict, names) -> dict[str, dict[str, float]]:
    """Absolute max and RMS of each tensor: the scale check printed after generation."""
    out = {}
    for name in names:
        if name in arrays:
            a = np.asarray(arrays[name], dtype=np.float64)
            out[name] = {"absmax": round(float(np.abs(a).max()), 4),
                         "rms": round(float(np.sqrt(np.mean(a ** 2))), 4)}
    return out


def generate(name: str, p: Preset, out: Path, seed: int) -> dict:
    """Write the checkpoint folder `out` (replaced atomically) and return a summary."""
    t0 = time.time()
    rng = preset_rng(seed, name)
    tmp = out.with_name(out.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)

    stats, sample_frames = make_dataset(p, rng)
    mk = WeightMaker(rng)
    calib_scale = make_backbone_weights(p, mk, calibration_batches(p, rng, stats))
    make_transformer_weights(p, mk)
    inputs = make_inputs(p, rng, sample_frames)

    write_json(tmp / "config.json", build_config(p), indent=4)
    if p.layout == "current":
        stio.save_file(mk.w, tmp / "model.safetensors", metadata={"format": "pt"})
        write_current_layout(p, tmp, stats)
    else:
        stio.save_file({**mk.w, **legacy_buffers(p, stats)}, tmp / "model.safetensors")
    t_write = time.time()

    ref = compute_reference(tmp, inputs, p)
    t_ref = time.time()
    png_files = []
    for cam in p.cameras:
        for i in range(p.samples):
            write_png(tmp / png_name(i, cam.key), inputs[f"input.{cam.key}.u8_nhwc"][i])
            png_files.append(png_name(i, cam.key))
    tensors = {**inputs, **{k: _f32(v) for k, v in ref.items()}}
    metadata = {
        "generator": "test/tools/make_test_checkpoint.py",
        "generator_sha256": file_sha256(Path(__file__)),
        "spec_forward_sha256": file_sha256(Path(spec_forward.__file__)),
        "reference": "spec_forward.py float64 forward, cast to F32",
        "reference_extensions": json.dumps(reference_extensions(p)),
        "config_preset": name,
        "preset": json.dumps(asdict(p)),
        "seed": str(seed),
        "layout": p.layout,
        "camera_keys": json.dumps([c.key for c in p.cameras]),
        "n_samples": str(p.samples),
        "temporal_ensemble_coeff": json.dumps(p.temporal_ensemble_coeff),
        "png_files": json.dumps(png_files),
        "torch_version": torch.__version__,
        "numpy_version": np.__version__,
    }
    stio.save_file(tensors, tmp / "reference.safetensors", metadata=metadata)
    write_readme(tmp, name, p, tensors)

    shutil.rmtree(out, ignore_errors=True)
    tmp.rename(out)
    return {
        "preset": name,
        "seconds": {"weights_and_files": round(t_write - t0, 2),
                    "reference_float64": round(t_ref - t_write, 2),
                    "total": round(time.time() - t0, 2)},
        "calibration_rms": {k: round(v, 3) for k, v in calib_scale.items()},
        "magnitudes": magnitudes(ref, SCALE_REPORT),
        "files_bytes": {f.name: f.stat().st_size for f in sorted(out.iterdir())
                        if not f.name.endswith(".png")},
    }


def write_readme(folder: Path, name: str, p: Preset, tensors: dict) -> None:
    """A short README like the fixtures' ones, so a failing test's data explains itself."""
    lines = [f"# {name} - generated ACT test checkpoint ({p.layout} layout)", "",
             f"{p.description}.", "",
             "Generated by `test/tools/make_test_checkpoint.py` (random weights of realistic "
             "scale, dataset-style statistics); reference outputs from the float64 forward of "
             "`shared/tools/act_reference/spec_forward.py` on these files. Compare FP32 results "
             "with a tolerance of about 1e-4 (relative to the tensor's magnitude).", "",
             "| tensor in reference.safetensors | dtype | shape |", "|---|---|---|"]
    for key in sorted(tensors):
        a = tensors[key]
        lines.append(f"| `{key}` | {'U8' if a.dtype == np.uint8 else 'F32'} | {list(a.shape)} |")
    (folder / "README.md").write_text("\n".join(lines) + "\n")


def png_name(sample: int, camera_key: str) -> str:
    return f"sample{sample}.{camera_key}.png"  # as in the fixtures


def file_sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


# -------------------------------------------------------------------------------------- self-check
def verify(folder: Path) -> dict:
    """Reload the folder from disk and check it against its reference.safetensors.

    Re-runs spec_forward in float32 (cheap, and an FP32 engine's view of the numbers): agreement
    with the float64 reference to ~1e-5 relative shows the files reload, the reference belongs to
    them, and the random model is well-conditioned enough to test an FP32 engine at 1e-4.
    Also checks the select_action tensors (online vs closed-form ensembling) and the PNGs.
    """
    for f in folder.glob("*.safetensors"):
        stio.check_file(f)
    ref = stio.load_file_numpy(folder / "reference.safetensors")
    meta = stio.load_metadata(folder / "reference.safetensors")
    p = preset_from_json(meta["preset"])
    cams = [c.key for c in p.cameras]
    ck = make_reference_checkpoint(folder, torch.float32)
    worst = {"output.action": 0.0, "output.action_normalized": 0.0}
    inter_rel = {}
    with torch.no_grad():
        for i in range(p.samples):
            images = {c: torch.from_numpy(ref[f"input.{c}"][i]) for c in cams}
            state = torch.from_numpy(ref[f"input.{STATE_KEY}"][i])
            env = torch.from_numpy(ref[f"input.{ENV_KEY}"][i]) if p.env_dim else None
            raw, norm, inter = run_forward(ck, images, state, env)
            for key, got in (("output.action", raw), ("output.action_normalized", norm)):
                want = ref[key][i]
                worst[key] = max(worst[key], relative_diff(got.numpy(), want))
            if i == 0:
                for k, v in inter.items():
                    if "sample0." + k in ref:
                        want = ref["sample0." + k]
                        inter_rel[k] = relative_diff(v.numpy().reshape(want.shape), want)
    report = {"max_rel_diff_float32_vs_reference": {**worst, **inter_rel}}
    bad = {k: v for k, v in report["max_rel_diff_float32_vs_reference"].items()
           if v > VERIFY_TOLERANCE}
    if p.temporal_ensemble_coeff is not None:
        chunks = ref["output.action"].astype(np.float64)
        online = temporal_ensemble(chunks, p.temporal_ensemble_coeff)
        closed = temporal_ensemble_closed_form(chunks, p.temporal_ensemble_coeff)
        report["temporal_ensemble_diff"] = float(np.abs(ref["temporal_ensemble.actions"]
                                                        - closed).max())
        if np.abs(online - closed).max() > 1e-9 or report["temporal_ensemble_diff"] > 1e-5:
            bad["temporal_ensemble.actions"] = report["temporal_ensemble_diff"]
    else:
        queue = ref["select_action.queue_sample0"]
        if not np.array_equal(queue, ref["output.action"][0, :p.n_action_steps]):
            bad["select_action.queue_sample0"] = 1.0
    for cam in cams:
        for i, u8 in enumerate(ref[f"input.{cam}.u8_nhwc"]):
            if not np.array_equal(read_png(folder / png_name(i, cam)), u8):
                bad[png_name(i, cam)] = 1.0
    report["ok"] = not bad
    report["failures"] = bad
    return report


def relative_diff(got: np.ndarray, want: np.ndarray) -> float:
    """max |got - want| / max(1, max |want|): absolute for O(1) tensors, relative for large ones."""
    want = want.astype(np.float64)
    return float(np.abs(got.astype(np.float64) - want).max() / max(1.0, np.abs(want).max()))


# --------------------------------------------------------------------------------------------- CLI
def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--preset", choices=sorted(PRESETS))
    ap.add_argument("--out", type=Path, help="checkpoint folder to (re)create")
    ap.add_argument("--shared", type=Path, default=REPO_ROOT.parent / "shared",
                    help="the shared/ folder with tools/act_reference (default: <repo>/../shared)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--samples", type=int, help="number of reference samples (preset default)")
    ap.add_argument("--list", action="store_true", help="list the presets and exit")
    ap.add_argument("--no-verify", action="store_true", help="skip the float32 reload self-check")
    ap.add_argument("--verify-only", type=Path, metavar="DIR",
                    help="only run the self-check on an existing folder")
    args = ap.parse_args()

    if args.list:
        for name, p in PRESETS.items():
            cams = ", ".join(f"{c.key} {c.height}x{c.width}" for c in p.cameras)
            print(f"{name:24s} {p.layout:7s} {p.vision_backbone} D{p.dim_model} "
                  f"{p.n_encoder_layers}+{p.n_decoder_layers} T{p.chunk_size} [{cams}] "
                  f"- {p.description}")
        return 0
    load_shared_tools(args.shared.resolve())
    if args.verify_only:
        report = verify(args.verify_only)
        print(json.dumps(report, indent=1))
        return 0 if report["ok"] else 1
    if not args.preset or not args.out:
        ap.error("--preset and --out are required (or --list / --verify-only)")
    preset = PRESETS[args.preset]
    if args.samples:
        preset.samples = args.samples
    if preset.temporal_ensemble_coeff is not None and preset.samples < 2:
        ap.error("temporal ensembling needs at least 2 samples")
    # The BN calibration runs float32 convs; one thread keeps their summation order, and so the
    # weights, independent of the core count (the float64 reference is single-threaded anyway).
    torch.set_num_threads(1)
    summary = generate(args.preset, preset, args.out.resolve(), args.seed)
    if not args.no_verify:
        t0 = time.time()
        summary["verify"] = verify(args.out.resolve())
        summary["seconds"]["verify_float32"] = round(time.time() - t0, 2)
    print(json.dumps(summary, indent=1))
    return 0 if summary.get("verify", {"ok": True})["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
