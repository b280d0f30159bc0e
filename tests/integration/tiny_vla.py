"""A tiny SmolVLA made here, offline, in the shape of lerobot/smolvla_base: a SmolVLM-shaped
backbone (its config, image processor and a word-level tokenizer carrying the special image tokens
SmolVLA reads) and a "pretrained" policy on three 32x32 cameras (camera1..3, as smolvla_base's) and
six joints, with its processors, saved as LeRobot saves a checkpoint. What the stack does with
lerobot/smolvla_base from the Hub, it does with this, without the Hub.

Run by the VLAs' environment's interpreter (.venv-vla: transformers), from the tests of the main one:
  tiny_vla.py make DIRECTORY        makes the backbone and the policy, prints the policy's path
  tiny_vla.py act CHECKPOINT TEXT.. the stack's policy on one fixed observation per task text:
                                    prints its cameras and one action per text (JSON)"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from so101 import contract

# The backbone's special tokens (SmolVLM's names; SmolVLA frames each image with the first two).
SPECIAL_TOKENS = {
    "fake_image_token": "<fake_token_around_image>",
    "global_image_token": "<global-img>",
    "image_token": "<image>",
    "end_of_utterance_token": "<end_of_utterance>",
    "video_token": "<video>",
}
IMAGE_SIZE = 32


def make_backbone(directory: Path) -> Path:
    """A SmolVLM-shaped config, image processor and tokenizer (every word of the contract's task
    texts) in `directory`: what --policy.vlm_model_name names."""
    from tokenizers import Tokenizer, models, normalizers, pre_tokenizers
    from transformers import (
        PreTrainedTokenizerFast,
        SmolVLMConfig,
        SmolVLMImageProcessor,
        SmolVLMProcessor,
        SmolVLMVideoProcessor,
    )

    vocab = {token: index for index, token in enumerate(["<pad>", "<unk>", "<|im_start|>", *SPECIAL_TOKENS.values()])}
    for task in contract.TASKS.values():
        for word in task.description.lower().replace(",", " ").split():
            vocab.setdefault(word, len(vocab))
    words = Tokenizer(models.WordLevel(vocab=vocab, unk_token="<unk>"))
    words.normalizer = normalizers.Lowercase()
    words.pre_tokenizer = pre_tokenizers.Whitespace()
    tokenizer = PreTrainedTokenizerFast(
        tokenizer_object=words,
        unk_token="<unk>",
        pad_token="<pad>",
        bos_token="<|im_start|>",
        eos_token="<end_of_utterance>",
        extra_special_tokens=SPECIAL_TOKENS,
    )
    edge = {"longest_edge": IMAGE_SIZE}
    processor = SmolVLMProcessor(
        image_processor=SmolVLMImageProcessor(size=edge, max_image_size=edge),
        tokenizer=tokenizer,
        video_processor=SmolVLMVideoProcessor(),
        image_seq_len=1,
    )
    config = SmolVLMConfig(
        vision_config={
            "hidden_size": 32,
            "intermediate_size": 64,
            "num_hidden_layers": 1,
            "num_attention_heads": 2,
            "image_size": IMAGE_SIZE,
            "patch_size": 8,
        },
        text_config={
            "model_type": "llama",
            "hidden_size": 64,
            "intermediate_size": 128,
            "num_hidden_layers": 2,
            "num_attention_heads": 4,
            "num_key_value_heads": 2,
            "head_dim": 16,
            "vocab_size": len(vocab),
            "max_position_embeddings": 512,
        },
        scale_factor=2,
        image_token_id=vocab["<image>"],
        vocab_size=len(vocab),
    )
    processor.save_pretrained(directory)
    config.save_pretrained(directory)
    return directory


def make_pretrained_smolvla(directory: Path, backbone: Path) -> Path:
    """A SmolVLA checkpoint (config, weights, processors) on `backbone`, as lerobot/smolvla_base is
    laid out: three cameras camera1..3, six-value state and action, chunks of 10."""
    from lerobot.configs import FeatureType, PolicyFeature
    from lerobot.policies.factory import make_pre_post_processors
    from lerobot.policies.smolvla.configuration_smolvla import SmolVLAConfig
    from lerobot.policies.smolvla.modeling_smolvla import SmolVLAPolicy

    config = SmolVLAConfig(
        vlm_model_name=str(backbone),
        load_vlm_weights=False,
        resize_imgs_with_padding=(IMAGE_SIZE, IMAGE_SIZE),
        num_vlm_layers=2,
        chunk_size=10,
        n_action_steps=10,
        num_steps=2,
        device="cpu",
        push_to_hub=False,
    )
    config.input_features = {
        "observation.state": PolicyFeature(FeatureType.STATE, (6,)),
        **{f"observation.images.camera{i}": PolicyFeature(FeatureType.VISUAL, (3, 256, 256)) for i in (1, 2, 3)},
    }
    config.output_features = {"action": PolicyFeature(FeatureType.ACTION, (6,))}
    SmolVLAPolicy(config).save_pretrained(directory)
    preprocessor, postprocessor = make_pre_post_processors(config, dataset_stats=None)
    preprocessor.save_pretrained(directory)
    postprocessor.save_pretrained(directory)
    return directory


def act_per_text(checkpoint: str, texts: list[str]) -> dict:
    """The stack's policy (so101.evaluate.policy.StackPolicy) on one fixed observation under each
    task text, with the same noise for the flow's sampling: only the text differs."""
    import numpy as np
    import torch

    from so101.evaluate.policy import StackPolicy

    policies = [StackPolicy(checkpoint, device="cpu", task=text) for text in texts]
    rng = np.random.default_rng(0)
    images = {name: rng.integers(0, 255, (48, 64, 3), dtype=np.uint8) for name in ("top", "wrist")}
    actions = []
    for policy in policies:
        policy.reset()
        torch.manual_seed(0)
        actions.append(np.asarray(policy.act(policy.observation(np.zeros(6), images)), dtype=float).tolist())
    return {"cameras": [[c.name, c.width, c.height] for c in policies[0].cameras], "actions": actions}


if __name__ == "__main__":
    command, target, *rest = sys.argv[1:]
    if command == "make":
        home = Path(target)
        print(make_pretrained_smolvla(home / "smolvla_tiny", make_backbone(home / "smolvlm_tiny")))
    elif command == "act":
        print(json.dumps(act_per_text(target, rest)))
    else:
        sys.exit(f"unknown command {command}")
