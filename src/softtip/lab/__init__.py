"""The virtual lab: registered systems' experiments run on their benches, each producing a dataset of trials."""

from softtip.lab.protocols import BenchKind, Protocol, load_protocol, protocol_from_dict, run_protocol

__all__ = ["BenchKind", "Protocol", "load_protocol", "protocol_from_dict", "run_protocol"]
