"""The virtual lab: the published experiments run on the twin, each producing a dataset of trials."""

from softtip.lab.protocols import DEFAULTS, Protocol, load_protocol, protocol_from_dict, run_protocol

__all__ = ["DEFAULTS", "Protocol", "load_protocol", "protocol_from_dict", "run_protocol"]
