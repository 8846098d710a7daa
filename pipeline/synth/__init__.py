"""Synthetic flights: a platform, a gimbal-tracked target, rendered video and telemetry written as real
vehicles write it (MAVLink tlog, ROS 1/2 bags, MCAP, mp4), with the ground truth. See docs/synth.md.

    from pipeline.synth import SynthConfig, generate
    generate(SynthConfig.load("configs/synth/group1.yaml"), "out/group1")
"""

from pipeline.synth.config import SynthConfig
from pipeline.synth.flight import SynthResult, generate

__all__ = ["SynthConfig", "SynthResult", "generate"]
