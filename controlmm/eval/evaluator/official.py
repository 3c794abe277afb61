"""The official HumanML3D evaluator (Guo et al. 2022), for users who have its files on disk.

Nothing is downloaded. The modules below are written for this project but are structurally
identical to the official ones (same layers, same parameter names and shapes), so
the released ``finest.tar`` loads with ``strict=True``:

- ``MovementConvEncoder(259, 512, 512)``: ``main.0`` Conv1d(259->512, k4, s2, p1), ``main.1`` Dropout 0.2,
  ``main.2`` LeakyReLU 0.2, ``main.3`` Conv1d(512->512, k4, s2, p1), Dropout, LeakyReLU; ``out_net``
  Linear(512->512);
- ``TextEncoderBiGRUCo(300, 15, 512, 512)``: ``pos_emb`` Linear(15->300) added to the GloVe vector,
  ``input_emb`` Linear(300->512), ``gru`` BiGRU(512), ``output_net`` [Linear(1024->512), LayerNorm,
  LeakyReLU, Linear(512->512)], ``hidden`` (2, 1, 512) initial state;
- ``MotionEncoderBiGRUCo(512, 1024, 512)``: ``input_emb`` Linear(512->1024), ``gru`` BiGRU(1024),
  ``output_net`` [Linear(2048->1024), LayerNorm, LeakyReLU, Linear(1024->512)], ``hidden`` (2, 1, 1024).

Files (MoMask/MaskControl ``prepare/download_evaluator.sh`` and ``download_glove.sh`` layout)::

    T2M/text_mot_match/model/finest.tar      {"movement_encoder", "text_encoder", "motion_encoder", "epoch"}
    T2M/Comp_v6_KLD005/meta/mean.npy, std.npy (263,) normalisation of the evaluator's input
    GLOVE/our_vab_data.npy                   (V, 300) GloVe vectors of the HumanML3D vocabulary
    GLOVE/our_vab_words.pkl, our_vab_idx.pkl word list and word -> row index

``T2M`` is ``checkpoints/t2m`` of a MoMask checkout; :func:`load_official_evaluator` accepts the
checkout root, ``checkpoints/``, or ``checkpoints/t2m`` itself, and finds ``glove/`` beside them.

Text input (the official word vectorizer): HumanML3D caption tokens ``word/POS``; at most 20 words
wrapped in ``sos/OTHER`` and ``eos/OTHER``, padded with ``unk/OTHER`` to 22; each token is its GloVe
vector (``unk``'s for unknown words) and a 15-d one-hot of its POS (unknown words: OTHER; words of the
five "VIP" lists replace their POS by Loc/Body/Obj/Act/Desc_VIP). Motion input: (features - mean) / std
without the 4 contact dims, zero-padded to 196 frames, GRU over m // 4 steps.
"""

from __future__ import annotations

import pickle
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.nn.utils.rnn import pack_padded_sequence

from controlmm.errors import InputFileError
from controlmm.eval.evaluator.base import MotionLike, TextLike, pad_normalized
from controlmm.eval.evaluator.words import tokenize
from controlmm.models.model_dir import load_state_strict
from controlmm.motion.normalization import Normalizer

POS_ENUMERATOR = {
    "VERB": 0,
    "NOUN": 1,
    "DET": 2,
    "ADP": 3,
    "NUM": 4,
    "AUX": 5,
    "PRON": 6,
    "ADJ": 7,
    "ADV": 8,
    "Loc_VIP": 9,
    "Body_VIP": 10,
    "Obj_VIP": 11,
    "Act_VIP": 12,
    "Desc_VIP": 13,
    "OTHER": 14,
}
VIP_WORDS = {
    "Loc_VIP": (
        "left",
        "right",
        "clockwise",
        "counterclockwise",
        "anticlockwise",
        "forward",
        "back",
        "backward",
        "up",
        "down",
        "straight",
        "curve",
    ),
    "Body_VIP": (
        "arm",
        "chin",
        "foot",
        "feet",
        "face",
        "hand",
        "mouth",
        "leg",
        "waist",
        "eye",
        "knee",
        "shoulder",
        "thigh",
    ),
    "Obj_VIP": (
        "stair",
        "dumbbell",
        "chair",
        "window",
        "floor",
        "car",
        "ball",
        "handrail",
        "baseball",
        "basketball",
    ),
    "Act_VIP": (
        "walk",
        "run",
        "swing",
        "pick",
        "bring",
        "kick",
        "put",
        "squat",
        "throw",
        "hop",
        "dance",
        "jump",
        "turn",
        "stumble",
        "stop",
        "sit",
        "lift",
        "lower",
        "raise",
        "wash",
        "stand",
        "kneel",
        "stroll",
        "rub",
        "bend",
        "balance",
        "flap",
        "jog",
        "shuffle",
        "lean",
        "rotate",
        "spin",
        "spread",
        "climb",
    ),
    "Desc_VIP": (
        "slowly",
        "carefully",
        "fast",
        "careful",
        "slow",
        "quickly",
        "happy",
        "angry",
        "sad",
        "happily",
        "angrily",
        "sadly",
    ),
}
MAX_TEXT_LEN = 20
WORD_DIM, POS_DIM, TEXT_HIDDEN, MOTION_HIDDEN, MOVEMENT_HIDDEN, EMBED_DIM = 300, 15, 512, 1024, 512, 512
DIM_POSE = 263
UNIT = 4


# -- the modules (official structure and names) -----------------------------------------------------
class MovementConvEncoder(nn.Module):
    def __init__(
        self,
        input_size: int = DIM_POSE - 4,
        hidden_size: int = MOVEMENT_HIDDEN,
        output_size: int = MOVEMENT_HIDDEN,
    ) -> None:
        super().__init__()
        self.main = nn.Sequential(
            nn.Conv1d(input_size, hidden_size, 4, 2, 1),
            nn.Dropout(0.2),
            nn.LeakyReLU(0.2),
            nn.Conv1d(hidden_size, output_size, 4, 2, 1),
            nn.Dropout(0.2),
            nn.LeakyReLU(0.2),
        )
        self.out_net = nn.Linear(output_size, output_size)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, T, 259) -> (B, T // 4, 512)."""
        return self.out_net(self.main(x.permute(0, 2, 1)).permute(0, 2, 1))


def _output_net(hidden: int, out: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Linear(hidden * 2, hidden), nn.LayerNorm(hidden), nn.LeakyReLU(0.2), nn.Linear(hidden, out)
    )


def _bigru(gru: nn.GRU, hidden: nn.Parameter, x: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
    packed = pack_padded_sequence(x, lengths.cpu(), batch_first=True, enforce_sorted=False)
    _, last = gru(packed, hidden.repeat(1, x.shape[0], 1))
    return torch.cat([last[0], last[1]], dim=-1)


class TextEncoderBiGRUCo(nn.Module):
    def __init__(
        self,
        word_size: int = WORD_DIM,
        pos_size: int = POS_DIM,
        hidden_size: int = TEXT_HIDDEN,
        output_size: int = EMBED_DIM,
    ) -> None:
        super().__init__()
        self.pos_emb = nn.Linear(pos_size, word_size)
        self.input_emb = nn.Linear(word_size, hidden_size)
        self.gru = nn.GRU(hidden_size, hidden_size, batch_first=True, bidirectional=True)
        self.output_net = _output_net(hidden_size, output_size)
        self.hidden = nn.Parameter(torch.randn(2, 1, hidden_size))

    def forward(
        self, word_embs: torch.Tensor, pos_onehot: torch.Tensor, cap_lens: torch.Tensor
    ) -> torch.Tensor:
        """(B, 22, 300), (B, 22, 15), (B,) -> (B, 512)."""
        x = self.input_emb(word_embs + self.pos_emb(pos_onehot))
        return self.output_net(_bigru(self.gru, self.hidden, x, cap_lens))


class MotionEncoderBiGRUCo(nn.Module):
    def __init__(
        self,
        input_size: int = MOVEMENT_HIDDEN,
        hidden_size: int = MOTION_HIDDEN,
        output_size: int = EMBED_DIM,
    ) -> None:
        super().__init__()
        self.input_emb = nn.Linear(input_size, hidden_size)
        self.gru = nn.GRU(hidden_size, hidden_size, batch_first=True, bidirectional=True)
        self.output_net = _output_net(hidden_size, output_size)
        self.hidden = nn.Parameter(torch.randn(2, 1, hidden_size))

    def forward(self, movements: torch.Tensor, m_lens: torch.Tensor) -> torch.Tensor:
        """(B, N, 512), steps (B,) -> (B, 512)."""
        return self.output_net(_bigru(self.gru, self.hidden, self.input_emb(movements), m_lens))


# -- GloVe word vectors -----------------------------------------------------------------------------
class _PlainUnpickler(pickle.Unpickler):
    """Reads the vocabulary pickles (lists/dicts of str and int) and refuses anything executable."""

    ALLOWED = {("numpy", "dtype"), ("numpy.core.multiarray", "scalar"), ("numpy._core.multiarray", "scalar")}

    def find_class(self, module: str, name: str) -> Any:  # a class or function, as pickle's
        if (module, name) in self.ALLOWED:
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"refusing to load {module}.{name}")


def _read_pickle(path: Path) -> Any:  # whatever the file holds (the callers check what they use)
    try:
        with open(path, "rb") as fh:
            return _PlainUnpickler(fh).load()
    except Exception as exc:  # noqa: BLE001 - any unreadable file is a user error
        raise InputFileError(f"cannot read '{path}': {type(exc).__name__}: {exc}") from None


class WordVectorizer:
    """``word/POS`` token -> (300-d GloVe vector, 15-d POS one-hot), as the official vectorizer."""

    def __init__(self, glove_dir: str | Path, prefix: str = "our_vab") -> None:
        glove_dir = Path(glove_dir)
        try:
            vectors = np.load(glove_dir / f"{prefix}_data.npy", allow_pickle=False)
        except Exception as exc:  # noqa: BLE001
            raise InputFileError(
                f"cannot read '{glove_dir / f'{prefix}_data.npy'}': {type(exc).__name__}"
            ) from None
        words = _read_pickle(glove_dir / f"{prefix}_words.pkl")
        index = _read_pickle(glove_dir / f"{prefix}_idx.pkl")
        if vectors.ndim != 2 or vectors.shape[1] != WORD_DIM:
            raise InputFileError(
                f"'{glove_dir / f'{prefix}_data.npy'}' must hold (V, {WORD_DIM}) vectors; got {vectors.shape}"
            )
        try:
            self.word2vec = {w: vectors[int(index[w])].astype(np.float32) for w in words}
        except (KeyError, IndexError, TypeError, ValueError) as exc:
            raise InputFileError(
                f"GloVe files in '{glove_dir}' disagree (word list vs index): {exc}"
            ) from None
        if "unk" not in self.word2vec:
            raise InputFileError(f"GloVe vocabulary in '{glove_dir}' has no 'unk' entry")

    @staticmethod
    def pos_onehot(pos: str) -> np.ndarray:
        vec = np.zeros(POS_DIM, dtype=np.float32)
        vec[POS_ENUMERATOR.get(pos, POS_ENUMERATOR["OTHER"])] = 1.0
        return vec

    def __getitem__(self, token: str) -> tuple[np.ndarray, np.ndarray]:
        word, _, pos = token.rpartition("/") if "/" in token else (token, "", "OTHER")
        if word not in self.word2vec:
            return self.word2vec["unk"], self.pos_onehot("OTHER")
        vip = next((key for key, values in VIP_WORDS.items() if word in values), None)
        return self.word2vec[word], self.pos_onehot(vip or pos)

    def sentence(self, tokens: Sequence[str]) -> tuple[np.ndarray, np.ndarray, int]:
        """Tokens -> word vectors (22, 300), POS one-hots (22, 15) and the length with sos/eos."""
        tokens = ["sos/OTHER"] + list(tokens[:MAX_TEXT_LEN]) + ["eos/OTHER"]
        length = len(tokens)
        tokens += ["unk/OTHER"] * (MAX_TEXT_LEN + 2 - length)
        pairs = [self[t] for t in tokens]
        return np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs]), length


# -- the evaluator ----------------------------------------------------------------------------------
class OfficialEvaluator:
    """The HumanML3D evaluator's three modules with its word vectorizer and normalisation."""

    def __init__(
        self,
        movement: MovementConvEncoder,
        text: TextEncoderBiGRUCo,
        motion: MotionEncoderBiGRUCo,
        words: WordVectorizer,
        normalizer: Normalizer,
        root: Path | None = None,
        device: str | torch.device = "cpu",
    ) -> None:
        self.device = torch.device(device)
        self.movement_encoder = movement.eval().requires_grad_(False).to(self.device)
        self.text_encoder = text.eval().requires_grad_(False).to(self.device)
        self.motion_encoder = motion.eval().requires_grad_(False).to(self.device)
        self.words, self.normalizer, self.root = words, normalizer, root
        self.dim = EMBED_DIM
        self.name = "official HumanML3D evaluator"
        self._warned = False

    def _tokens(self, caption: TextLike) -> list[str]:
        tokens = getattr(caption, "tokens", None)
        if tokens:
            return list(tokens)
        if not self._warned:
            warnings.warn(
                "the official evaluator reads HumanML3D 'word/POS' tokens; captions given as plain text "
                "are split into words tagged OTHER (less faithful)",
                stacklevel=3,
            )
            self._warned = True
        return [f"{w}/OTHER" for w in tokenize(str(getattr(caption, "text", caption)))]

    @torch.no_grad()
    def embed_texts(self, captions: Sequence[TextLike], batch_size: int = 256) -> np.ndarray:
        out = []
        for start in range(0, len(captions), batch_size):
            rows = [self.words.sentence(self._tokens(c)) for c in captions[start : start + batch_size]]
            word = torch.from_numpy(np.stack([r[0] for r in rows])).to(self.device)
            pos = torch.from_numpy(np.stack([r[1] for r in rows])).to(self.device)
            lengths = torch.tensor([r[2] for r in rows])
            out.append(self.text_encoder(word, pos, lengths).double().cpu().numpy())
        return np.concatenate(out) if out else np.zeros((0, self.dim))

    @torch.no_grad()
    def embed_motions(self, motions: Sequence[MotionLike], batch_size: int = 256) -> np.ndarray:
        out = []
        for start in range(0, len(motions), batch_size):
            x, lengths = pad_normalized(motions[start : start + batch_size], self.normalizer, UNIT)
            movements = self.movement_encoder(x[..., :-4].to(self.device))
            steps = torch.div(lengths, UNIT, rounding_mode="floor")
            out.append(self.motion_encoder(movements, steps).double().cpu().numpy())
        return np.concatenate(out) if out else np.zeros((0, self.dim))


def _first(candidates: list[Path]) -> Path | None:
    return next((p for p in candidates if p.is_file()), None)


def official_layout(root: str | Path) -> dict[str, Path]:
    """Locate the official files under ``root``; one-line error naming what is missing and where it looked."""
    root = Path(root)
    t2m_dirs = [root, root / "t2m", root / "checkpoints" / "t2m"]
    finest = _first([d / "text_mot_match" / "model" / "finest.tar" for d in t2m_dirs])
    if finest is None:
        raise InputFileError(
            f"official HumanML3D evaluator: no text_mot_match/model/finest.tar under '{root}' "
            f"(looked in {', '.join(str(d) for d in t2m_dirs)})"
        )
    t2m = finest.parents[2]
    files = {"finest": finest}
    for name in ("mean", "std"):
        path = t2m / "Comp_v6_KLD005" / "meta" / f"{name}.npy"
        if not path.is_file():
            raise InputFileError(
                f"official HumanML3D evaluator: missing {path} (the evaluator's normalisation)"
            )
        files[name] = path
    glove_dirs = list(
        dict.fromkeys([root / "glove", t2m / "glove", t2m.parent / "glove", t2m.parent.parent / "glove"])
    )
    names = ("our_vab_data.npy", "our_vab_words.pkl", "our_vab_idx.pkl")
    glove = next((d for d in glove_dirs if all((d / n).is_file() for n in names)), None)
    if glove is None:
        partial = next((d for d in glove_dirs if d.is_dir()), None)
        missing = [n for n in names if partial is None or not (partial / n).is_file()]
        where = f"'{partial}' lacks" if partial else "no glove/ folder with"
        raise InputFileError(
            f"official HumanML3D evaluator: {where} {', '.join(missing)} (looked in "
            f"{', '.join(str(d) for d in glove_dirs)})"
        )
    files["glove"] = glove
    return files


def load_official_evaluator(root: str | Path, device: str | torch.device = "cpu") -> OfficialEvaluator:
    """Load the official evaluator from a MoMask-style checkout (see the module docstring)."""
    files = official_layout(root)
    try:
        ckpt = torch.load(files["finest"], map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001
        raise InputFileError(f"'{files['finest']}' is corrupt or unreadable ({type(exc).__name__})") from None
    movement, text, motion = MovementConvEncoder(), TextEncoderBiGRUCo(), MotionEncoderBiGRUCo()
    modules: dict[str, nn.Module] = {
        "movement_encoder": movement,
        "text_encoder": text,
        "motion_encoder": motion,
    }
    for key, module in modules.items():
        if not isinstance(ckpt, dict) or key not in ckpt:
            raise InputFileError(
                f"'{files['finest']}' has no '{key}' state dict (keys: "
                f"{', '.join(map(str, ckpt)) if isinstance(ckpt, dict) else type(ckpt).__name__})"
            )
        load_state_strict(module, {k: v.float() for k, v in ckpt[key].items()}, f"{files['finest']}:{key}")
    normalizer = Normalizer.load(files["mean"], files["std"])
    words = WordVectorizer(files["glove"])
    return OfficialEvaluator(
        movement,
        text,
        motion,
        words,
        normalizer,
        Path(root),
        device,
    )
