"""Configurations of the MoMask base models, and the named presets.

Three presets share one architecture and differ only in size:

- ``paper``: the released MoMask models (RVQ-VAE ``rvq_nq6_dc512_nc512_noshare_qdp0.2``, masked
  transformer ``t2m_nlayer8_nhead6_ld384_ff1024_cdp0.1_rvq6ns``, residual transformer
  ``tres_nlayer8_ld384_ff1024_rvq6ns_cdp0.2_sw``), parameter for parameter, with CLIP ViT-B/32 text
  features (512-d). Training schedules follow the official defaults (GPU scale).
- ``demo``: the same modules scaled down so that every training stage of the embedded default model
  (tokenizer, transformer, residual, plus the later control branch and evaluator) runs on 2 CPU cores in
  about two hours in total and the shipped model stays under 25 MiB (weights stored as float16).
- ``tiny``: a few thousand parameters per module, for tests and smoke runs only.

Every field is a plain value so a config round-trips through ``model.json`` (``asdict`` /
``from_dict``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any, TypedDict, TypeVar

from controlmm.errors import ControlMMError
from controlmm.text.config import CLIP_MODEL_ID, TEXT_ENCODER_DIMS, TextEncoderConfig

T = TypeVar("T")


@dataclass(frozen=True)
class TokenizerConfig:
    """RVQ-VAE (MoMask ``RVQVAE``): 1-D conv encoder/decoder around a residual quantizer.

    The encoder maps (B, T, 263) normalised features to (B, T / 2**down_t, code_dim) latents.
    """

    input_dim: int = 263
    width: int = 512
    code_dim: int = 512  # = official output_emb_width = code_dim
    nb_code: int = 512
    num_quantizers: int = 6
    down_t: int = 2
    stride_t: int = 2
    depth: int = 3
    dilation_growth_rate: int = 3
    resnet_dropout: float = 0.2
    mu: float = 0.99  # EMA decay of the codebooks
    quantize_dropout_prob: float = 0.2
    sample_codebook_temp: float = 0.5  # Gumbel temperature of the training-time code choice

    @property
    def downsample(self) -> int:
        """Frames per token (4 for the released model)."""
        return self.stride_t**self.down_t


@dataclass(frozen=True)
class TransformerConfig:
    """Text-conditioned masked (base-layer) transformer (MoMask ``MaskTransformer``).

    ``text_norm`` (not in MoMask): a LayerNorm on the text vector before ``cond_emb``. MiniLM sentence
    vectors are L2-normalised (components ~0.05) where MoMask feeds CLIP's unnormalised, so with the
    same N(0, 0.02) init the MiniLM condition token starts much weaker than MoMask's; the LayerNorm
    gives every text vector unit variance (components ~1). Off for the ``paper`` preset and official
    checkpoints.

    ``pooled_row`` (not in MoMask; models on MiniLM token states only): besides one row per token
    state, one condition row for the states' pooled sentence vector (MiniLM's own pooling) through its
    own LayerNorm and Linear. The two views of a caption fail on different held-out wordings
    (docs/benchmarks-history.md, "Sentence vector and token states").

    ``relative_positions`` (not in MoMask): K > 0 adds a learned per-head attention bias for the offset
    between two motion tokens, clipped at K tokens (:mod:`controlmm.models.relative_position`); 0 = off.

    ``token_drop_prob`` (not in MoMask; models on MiniLM token states only): word dropout while
    training: each token state of a caption is zeroed (so masked as padding) with this probability,
    so the model cannot lean on one word of the training wording; 0 = off.
    """

    nb_code: int = 512
    code_dim: int = 512  # width of token_emb (ids and soft embeddings live in this space)
    latent_dim: int = 384
    ff_size: int = 1024
    num_layers: int = 8
    num_heads: int = 6
    dropout: float = 0.2
    cond_drop_prob: float = 0.1
    text_dim: int = 512  # 512 for CLIP ViT-B/32, 384 for MiniLM
    max_len: int = 5000  # rows of the sinusoidal table (official 5000)
    text_norm: bool = False
    pooled_row: bool = (
        False  # with text token states: one more condition row for their pooled sentence vector
    )
    relative_positions: int = 0  # K > 0: learned attention bias per token offset, clipped at K tokens
    token_drop_prob: float = 0.0  # with text token states: training-time dropout of single token states

    @property
    def mask_id(self) -> int:
        return self.nb_code

    @property
    def pad_id(self) -> int:
        return self.nb_code + 1


@dataclass(frozen=True)
class ResidualConfig:
    """Residual transformer (MoMask ``ResidualTransformer``, shared/tied projections)."""

    nb_code: int = 512
    code_dim: int = 512
    num_quantizers: int = 6
    latent_dim: int = 384
    ff_size: int = 1024
    num_layers: int = 8
    num_heads: int = 6
    dropout: float = 0.2
    cond_drop_prob: float = 0.2
    text_dim: int = 512
    max_len: int = 5000
    text_norm: bool = False  # as TransformerConfig.text_norm

    @property
    def pad_id(self) -> int:
        return self.nb_code


CONTROL_JOINT_SETS: dict[str, tuple[int, ...]] = {"pelvis": (0,), "all": (0, 10, 11, 15, 20, 21)}
"""Joints the motion control model sees, as in the released MaskControl models: pelvis only, or pelvis,
feet, head, wrists."""


@dataclass(frozen=True)
class ControlConfig:
    """Motion control model (ControlMM's ControlNet branch, MaskControl ``ControlTransformer``).

    ``joints``: ``"all"`` (joints 0, 10, 11, 15, 20, 21: 36 input channels, the official all-joint
    model) or ``"pelvis"`` (6 channels, the official pelvis model). The control encoder is the
    tokenizer's ``Encoder`` class with the tokenizer's width and downsampling; the trainable
    transformer copy has the masked transformer's size.
    """

    joints: str = "all"
    encoder_dropout: float = 0.2

    @property
    def joint_ids(self) -> tuple[int, ...]:
        return CONTROL_JOINT_SETS[self.joints]

    @property
    def channels(self) -> int:
        """Input channels of ``encoder_control``: relative and absolute xyz of each joint (6 or 36)."""
        return 6 * len(self.joint_ids)


@dataclass(frozen=True)
class TokenViewConfig:
    """A second masked transformer on MiniLM's token states, ensembled with the sentence-vector one.

    Not in MoMask. MiniLM gives two views of a caption: the pooled sentence vector (what ``transformer``
    reads) and the token states (what this transformer reads, at most ``tokens`` per caption). The two
    fail on different held-out wordings, so text-only decoding (``generate``) averages their
    classifier-free-guided log-probabilities at every iteration:
    ``(1 - weight) * log p_sentence + weight * log p_tokens`` (docs/benchmarks-history.md, "Sentence
    vector and token states"). The part (``token_transformer.pt``, ``controlmm train token-transformer``) is
    optional: without it decoding uses ``transformer`` alone. The motion control model extends
    ``transformer`` only, so ``generate_controlled`` (whatever its settings) does not use it.
    """

    transformer: TransformerConfig
    tokens: int = 32
    weight: float = 0.5


BUCKETED_STAGES = ("transformer", "token_transformer", "residual")
"""Stages whose batches are trimmed to their longest clip, where length bucketing saves compute."""


@dataclass(frozen=True)
class StageSchedule:
    """Optimisation of one training stage (AdamW, linear warm-up, step decay).

    lr(it) = lr * min(1, (it + 1) / (warmup + 1)) * gamma ** (number of milestones <= it).
    """

    iters: int
    batch_size: int
    lr: float = 2e-4
    betas: tuple[float, float] = (0.9, 0.99)
    weight_decay: float = 0.0
    warmup: int = 2000
    milestones: tuple[int, ...] = ()
    gamma: float = 0.1
    checkpoint_every: int = 500
    window: int = 64  # tokenizer only: training window in frames
    limb_end_weight: float = 0.0  # tokenizer only: extra loss on ankles, feet, wrists (training.tokenizer)
    head_weight: float = 0.0  # tokenizer only: extra loss on the neck -> head direction (0, 0: MoMask's loss)
    bucket: int = 0  # transformer/residual: length bucketing over this many batches (0 = random batches)


@dataclass(frozen=True)
class ModelConfig:
    """Everything needed to rebuild a model directory's modules and train them."""

    preset: str
    tokenizer: TokenizerConfig
    transformer: TransformerConfig
    residual: ResidualConfig
    text_encoder: TextEncoderConfig = field(default_factory=TextEncoderConfig)
    control: ControlConfig = field(default_factory=ControlConfig)
    storage_dtype: str = "float32"  # dtype of the weights written to the model directory
    feat_bias: float = 5.0  # std of dims 0-3 and 259-262 divided by feat_bias ** feat_bias_times
    feat_bias_times: int = 2  # the official code applies feat_bias twice (Std/25)
    schedules: dict[str, StageSchedule] = field(default_factory=dict)
    token_view: TokenViewConfig | None = None  # optional token-state transformer (TokenViewConfig)

    def __post_init__(self) -> None:
        check_consistent(self)

    def with_text_encoder(self, text: TextEncoderConfig) -> ModelConfig:
        """This config conditioned on another text encoder (text_dim follows)."""
        dim = text.dim
        view = self.token_view
        if view is not None:  # token states are MiniLM's
            view = (
                replace(view, transformer=replace(view.transformer, text_dim=dim))
                if text.name == "minilm"
                else None
            )
        return replace(
            self,
            text_encoder=text,
            transformer=replace(self.transformer, text_dim=dim),
            residual=replace(self.residual, text_dim=dim),
            token_view=view,
        )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ModelConfig:
        try:
            return cls(
                preset=str(data["preset"]),
                tokenizer=_from_dict(TokenizerConfig, data["tokenizer"]),
                transformer=_from_dict(TransformerConfig, data["transformer"]),
                residual=_from_dict(ResidualConfig, data["residual"]),
                text_encoder=_from_dict(TextEncoderConfig, data.get("text_encoder", {})),
                control=_from_dict(ControlConfig, data.get("control", {})),
                storage_dtype=str(data.get("storage_dtype", "float32")),
                feat_bias=float(data.get("feat_bias", 5.0)),
                feat_bias_times=int(data.get("feat_bias_times", 2)),
                schedules={k: _schedule_from_dict(v) for k, v in data.get("schedules", {}).items()},
                token_view=_token_view_from_dict(data.get("token_view")),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ControlMMError(f"invalid model configuration: {type(exc).__name__}: {exc}") from exc


def _from_dict(cls: type[T], data: dict[str, Any]) -> T:
    names = {f.name for f in fields(cls)}  # type: ignore[arg-type]
    unknown = set(data) - names
    if unknown:
        raise ValueError(f"unknown {cls.__name__} fields: {', '.join(sorted(unknown))}")
    return cls(**data)


def _token_view_from_dict(data: dict[str, Any] | None) -> TokenViewConfig | None:
    if data is None:
        return None
    data = dict(data)
    data["transformer"] = _from_dict(TransformerConfig, data["transformer"])
    return _from_dict(TokenViewConfig, data)


def _schedule_from_dict(data: dict[str, Any]) -> StageSchedule:
    data = dict(data)
    data["betas"] = tuple(data.get("betas", (0.9, 0.99)))
    data["milestones"] = tuple(data.get("milestones", ()))
    return _from_dict(StageSchedule, data)


def check_consistent(cfg: ModelConfig) -> None:
    """Raise a one-line error when the parts of a config do not fit together."""
    tok, tr, res = cfg.tokenizer, cfg.transformer, cfg.residual
    transformers = [tr] if cfg.token_view is None else [tr, cfg.token_view.transformer]
    if cfg.text_encoder.name not in TEXT_ENCODER_DIMS:
        raise ControlMMError(
            f"unknown text encoder '{cfg.text_encoder.name}'; allowed: {', '.join(TEXT_ENCODER_DIMS)}"
        )
    if cfg.control.joints not in CONTROL_JOINT_SETS:
        raise ControlMMError(
            f"unknown control joint set '{cfg.control.joints}'; allowed: {', '.join(CONTROL_JOINT_SETS)}"
        )
    if cfg.text_encoder.tokens and (
        cfg.text_encoder.name != "minilm" or not 1 <= cfg.text_encoder.tokens <= 128
    ):
        raise ControlMMError(
            f"text encoder tokens must be 0 (sentence vectors) or 1..128 with minilm; got "
            f"{cfg.text_encoder.tokens} with {cfg.text_encoder.name}"
        )
    if tr.pooled_row and not cfg.text_encoder.tokens:
        raise ControlMMError("transformer pooled_row needs text token states (text encoder tokens > 0)")
    for t in transformers:
        if not 0.0 <= t.token_drop_prob < 1.0:
            raise ControlMMError(f"transformer token_drop_prob must be in [0, 1); got {t.token_drop_prob}")
    if cfg.token_view is not None:
        view = cfg.token_view
        if cfg.text_encoder.name != "minilm" or not 1 <= view.tokens <= 128:
            raise ControlMMError(
                f"token_view needs the minilm text encoder and 1..128 tokens; got {view.tokens} "
                f"with {cfg.text_encoder.name}"
            )
        if not 0.0 < view.weight < 1.0:
            raise ControlMMError(f"token_view weight must be between 0 and 1 (exclusive); got {view.weight}")
        if (view.transformer.nb_code, view.transformer.code_dim, view.transformer.text_dim) != (
            tok.nb_code,
            tok.code_dim,
            cfg.text_encoder.dim,
        ):
            raise ControlMMError(
                "inconsistent model configuration: the token_view transformer's nb_code, code_dim "
                "and text_dim must match the tokenizer and the text encoder"
            )
    for name, schedule in cfg.schedules.items():
        if schedule.bucket < 0 or (schedule.bucket and name not in BUCKETED_STAGES):
            raise ControlMMError(
                f"schedule '{name}': bucket must be 0, or a positive number of batches for "
                f"{', '.join(BUCKETED_STAGES)}; got {schedule.bucket}"
            )
    if cfg.text_encoder.precision not in ("float32", "float16"):
        raise ControlMMError(
            f"text encoder precision must be float32 or float16; got {cfg.text_encoder.precision}"
        )
    checks = [
        (tr.nb_code == tok.nb_code == res.nb_code, "nb_code must match across tokenizer and transformers"),
        (
            tr.code_dim == tok.code_dim == res.code_dim,
            "code_dim must match across tokenizer and transformers",
        ),
        (res.num_quantizers == tok.num_quantizers, "residual num_quantizers must equal the tokenizer's"),
        (tok.num_quantizers >= 3, "the residual transformer needs at least 3 quantizers"),
        (
            tr.text_dim == res.text_dim == cfg.text_encoder.dim,
            f"text_dim must equal the text encoder's size ({cfg.text_encoder.dim})",
        ),
        (tr.latent_dim % tr.num_heads == 0, "transformer latent_dim must be divisible by num_heads"),
        (
            min(t.relative_positions for t in transformers) >= 0,
            "relative_positions must be 0 (off) or a positive number of tokens",
        ),
        (res.latent_dim % res.num_heads == 0, "residual latent_dim must be divisible by num_heads"),
        (cfg.storage_dtype in ("float32", "float16"), "storage_dtype must be float32 or float16"),
    ]
    for ok, message in checks:
        if not ok:
            raise ControlMMError(f"inconsistent model configuration: {message}")


def _paper() -> ModelConfig:
    schedules = {
        # 50 epochs of 64-frame windows at batch 256 is about 300k iterations (milestones 150k/250k).
        "tokenizer": StageSchedule(
            iters=300_000,
            batch_size=256,
            lr=2e-4,
            weight_decay=0.0,
            warmup=2000,
            milestones=(150_000, 250_000),
            gamma=0.05,
            checkpoint_every=2000,
        ),
        # 500 epochs of HumanML3D at batch 64 is about 200k iterations.
        "transformer": StageSchedule(
            iters=200_000,
            batch_size=64,
            lr=2e-4,
            weight_decay=1e-5,
            warmup=2000,
            milestones=(50_000,),
            gamma=0.1,
            checkpoint_every=2000,
        ),
        "residual": StageSchedule(
            iters=200_000,
            batch_size=64,
            lr=2e-4,
            weight_decay=1e-5,
            warmup=2000,
            milestones=(50_000,),
            gamma=0.1,
            checkpoint_every=2000,
        ),
        # MaskControl train_ctrlnet.py: AdamW 2e-4, betas (0.9, 0.99), wd 1e-5, warm-up 2000, x0.1 at 50k.
        "control": StageSchedule(
            iters=200_000,
            batch_size=64,
            lr=2e-4,
            weight_decay=1e-5,
            warmup=2000,
            milestones=(50_000,),
            gamma=0.1,
            checkpoint_every=2000,
        ),
    }
    return ModelConfig(
        preset="paper",
        tokenizer=TokenizerConfig(),
        transformer=TransformerConfig(),
        residual=ResidualConfig(),
        text_encoder=TextEncoderConfig(name="clip", weights=CLIP_MODEL_ID),
        storage_dtype="float32",
        schedules=schedules,
    )


class _SharedFields(TypedDict):
    """The fields a preset gives both transformers (and the token-state member) alike."""

    nb_code: int
    code_dim: int
    latent_dim: int
    ff_size: int
    num_heads: int
    dropout: float
    text_dim: int
    max_len: int


class _SharedFieldsWithDepth(_SharedFields):
    num_layers: int


def _demo() -> ModelConfig:
    tok = TokenizerConfig(width=128, code_dim=128, nb_code=512, num_quantizers=6)
    common = _SharedFields(
        nb_code=512,
        code_dim=128,
        latent_dim=256,
        ff_size=512,
        num_heads=4,
        dropout=0.1,
        text_dim=384,
        max_len=64,
    )
    # Measured on the 49-family corpus when the shipped default was trained (fp32, 2 cores, one stage at
    # a time): tokenizer 3.4 it/s on 1 thread (17.5 min), residual 3.5 it/s (29.6 min), transformer
    # 2.8 it/s (59.0 min), control 1.6 it/s (16.1 min), token-state transformer 2.5 it/s (20.8 min):
    # 143 min in all (docs/model-card.md). The transformer and residual schedules are 1.5x those of the
    # 32-family corpus: at 6,400 / 4,000 iterations both fitted the new tokens worse (docs/BENCHMARKS.md,
    # "Candidate r34r6"). Both masked transformers use a relative position bias of 16 tokens
    # (docs/benchmarks-history.md, "Relative positions"); the residual transformer does not.
    schedules = {
        # The extra loss terms keep head turns, claps, punches and kicks through the tokenizer
        # (docs/BENCHMARKS.md, "Tokenizer loss").
        "tokenizer": StageSchedule(
            iters=3500,
            batch_size=64,
            lr=1e-3,
            warmup=200,
            milestones=(2300,),
            gamma=0.2,
            checkpoint_every=250,
            limb_end_weight=6.0,
            head_weight=2.0,
        ),
        "transformer": StageSchedule(
            iters=9600,
            batch_size=64,
            lr=6e-4,
            weight_decay=1e-5,
            warmup=200,
            milestones=(7680,),
            gamma=0.2,
            checkpoint_every=250,
            bucket=16,
        ),
        "residual": StageSchedule(
            iters=6000,
            batch_size=64,
            lr=6e-4,
            weight_decay=1e-5,
            warmup=100,
            milestones=(4800,),
            gamma=0.2,
            checkpoint_every=250,
            bucket=16,
        ),
        # The optional token-state transformer (token_view), partly warm-started from the transformer.
        "token_transformer": StageSchedule(
            iters=3000,
            batch_size=64,
            lr=6e-4,
            weight_decay=1e-5,
            warmup=200,
            milestones=(2400,),
            gamma=0.2,
            checkpoint_every=250,
            bucket=16,
        ),
        # Sized from the measured control-stage throughput (docs/models.md, "Motion control model").
        "control": StageSchedule(
            iters=1500,
            batch_size=32,
            lr=3e-4,
            weight_decay=1e-5,
            warmup=100,
            milestones=(1200,),
            gamma=0.2,
            checkpoint_every=100,
        ),
    }
    return ModelConfig(
        preset="demo",
        tokenizer=tok,
        transformer=TransformerConfig(
            num_layers=4, cond_drop_prob=0.1, text_norm=True, relative_positions=16, **common
        ),
        residual=ResidualConfig(num_layers=3, num_quantizers=6, cond_drop_prob=0.2, text_norm=True, **common),
        text_encoder=TextEncoderConfig(name="minilm"),
        storage_dtype="float16",
        schedules=schedules,
        token_view=TokenViewConfig(
            TransformerConfig(
                num_layers=3, cond_drop_prob=0.1, text_norm=True, relative_positions=16, **common
            ),
            tokens=32,
            weight=0.5,
        ),
    )


def _tiny() -> ModelConfig:
    tok = TokenizerConfig(width=32, code_dim=16, nb_code=32, num_quantizers=3, resnet_dropout=0.0)
    common = _SharedFieldsWithDepth(
        nb_code=32,
        code_dim=16,
        latent_dim=32,
        ff_size=64,
        num_layers=2,
        num_heads=2,
        dropout=0.0,
        text_dim=384,
        max_len=64,
    )
    schedules = {
        name: StageSchedule(
            iters=40,
            batch_size=8,
            lr=2e-3,
            warmup=5,
            checkpoint_every=10,
            window=32,
            bucket=2 if name in BUCKETED_STAGES else 0,
        )
        for name in ("tokenizer", "transformer", "token_transformer", "residual", "control")
    }
    return ModelConfig(
        preset="tiny",
        tokenizer=tok,
        transformer=TransformerConfig(cond_drop_prob=0.1, **common),
        residual=ResidualConfig(num_quantizers=3, cond_drop_prob=0.2, **common),
        text_encoder=TextEncoderConfig(name="minilm"),
        storage_dtype="float32",
        schedules=schedules,
        token_view=TokenViewConfig(TransformerConfig(cond_drop_prob=0.1, **common), tokens=16),
    )


PRESETS: dict[str, Callable[[], ModelConfig]] = {"paper": _paper, "demo": _demo, "tiny": _tiny}
"""Preset name -> factory of its :class:`ModelConfig`."""


def preset_config(name: str) -> ModelConfig:
    """The :class:`ModelConfig` of a named preset (``paper``, ``demo``, ``tiny``)."""
    if name not in PRESETS:
        raise ControlMMError(f"unknown preset '{name}'; allowed: {', '.join(PRESETS)}")
    return PRESETS[name]()
