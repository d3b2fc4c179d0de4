"""The "locate human" dialogue of ``EmbodiedAdhoc/ToxicWaste-v0``: the robot asks, the human answers through a
speech channel (``comms.channels``), and the lines of the dialogue are kept for the recording."""

from __future__ import annotations

import os

import numpy as np

from embodied_adhoc.errors import ConfigError

SPEECH_KINDS = ("channel", "audio", "perfect")


class SpeechTurn:
    """One question-answer per "locate human": ``ask(true_human_node, rng) -> (node or None, lines, wav)``."""

    def __init__(self, channel, kind: str):
        self.channel, self.kind = channel, kind

    def ask(
        self, true_human_node: int, rng: np.random.Generator
    ) -> tuple[int | None, list[str], bytes | None]:
        from embodied_adhoc.comms.robot_speech import WHERE_ARE_YOU
        from embodied_adhoc.comms.synthesis import wav_bytes
        from embodied_adhoc.comms.vocabulary import NODE_NAMES

        reply = self.channel.reply(int(true_human_node), rng)
        heard = "no location" if reply.node is None else f"{reply.node} {NODE_NAMES[reply.node]}"
        lines = [f'robot: "{WHERE_ARE_YOU}"']
        if reply.phrase is not None:
            lines.append(f'human: "{reply.phrase}"')
        if reply.transcript is not None:
            lines.append(f'recognised: "{reply.transcript}"')
        lines.append(f"heard node: {heard} ({self.kind}; true node {true_human_node})")
        wav = None if reply.audio is None else wav_bytes(reply.audio, reply.sample_rate)
        return reply.node, lines, wav


def make_speech(kind: str, confusion: str | os.PathLike) -> SpeechTurn:
    """The env's ``speech`` option: "channel" samples ``confusion`` (the agents' own observation model),
    "audio" runs synthesis and recognition on every query, "perfect" always hears the true node."""
    from embodied_adhoc.comms.channels import make_channel

    if kind not in SPEECH_KINDS:
        raise ConfigError(f"speech={kind!r} unknown; use one of {', '.join(SPEECH_KINDS)}")
    channel = make_channel(kind, confusion=str(confusion)) if kind == "channel" else make_channel(kind)
    return SpeechTurn(channel, kind)
