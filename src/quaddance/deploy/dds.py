"""DDS for the Go2 (unitree_sdk2 over Cyclone DDS), set up in one place.

Optional: ``pip install 'quaddance[go2]'`` installs the SDK (PyPI ``unitree-sdk2py-dimos``, a
fork of Unitree's unitree_sdk2_python that runs on cyclonedds 11; module ``unitree_sdk2py``);
it is imported only when a Go2 backend or simulator runs.

The SDK's channels (topics, its RPC clients and servers) all live in one Cyclone DDS domain
per process, made once by ``ChannelFactoryInitialize(domain, iface)``. That call builds its
Cyclone configuration from a template naming the interface; `init_dds` puts quaddance's
configuration in the template first, so that the SDK's own initialisation runs with it:

- a robot's wired interface (``--network eth0``): that interface only, Cyclone's defaults
  otherwise (multicast discovery, as the robot does);
- loopback (tests, the simulators): multicast off and 127.0.0.1 the only peer, so that no
  packet leaves 127.0.0.0/8 and nothing on the machine's other networks can join.
"""

from __future__ import annotations

from typing import Any

from quaddance.errors import QuaddanceError

#: The domain a Go2 speaks on (unitree_sdk2's default).
GO2_DOMAIN_ID = 0

_CONFIG = """<?xml version="1.0" encoding="UTF-8" ?>
<CycloneDDS xmlns="https://cdds.io/config">
  <Domain Id="any">
    <General>
      <Interfaces><NetworkInterface name="{iface}"{multicast}/></Interfaces>{general}
    </General>{discovery}
  </Domain>
</CycloneDDS>"""
_LOOPBACK_GENERAL = "\n      <AllowMulticast>false</AllowMulticast>"
_LOOPBACK_DISCOVERY = """
    <Discovery>
      <ParticipantIndex>auto</ParticipantIndex>
      <Peers><Peer Address="127.0.0.1"/></Peers>
    </Discovery>"""

_initialized: tuple[str, int] | None = None  #: this process's (interface, domain)
_participant: Any = None  #: this process's participant for `polled_reader`


def load_sdk2() -> None:
    """Import the SDK (and with it cyclonedds), or raise one clear error saying how to get it."""
    try:
        import unitree_sdk2py  # noqa: F401
    except ImportError as err:
        raise QuaddanceError(
            f"the Go2 needs unitree_sdk2py and cyclonedds ({err}): pip install 'quaddance[go2]'"
        ) from None


def is_loopback(iface: str) -> bool:
    """Whether ``iface`` names the loopback interface (``lo`` on Linux, ``lo0`` on macOS)."""
    return iface.startswith("lo")


def cyclonedds_config(iface: str) -> str:
    """The Cyclone DDS XML for the network interface ``iface`` (see the module's doc)."""
    if not iface or any(c in iface for c in "<>\"'& "):
        raise QuaddanceError(f"--network: {iface!r} is not a network interface name")
    if is_loopback(iface):
        return _CONFIG.format(
            iface=iface,
            multicast=' multicast="false"',
            general=_LOOPBACK_GENERAL,
            discovery=_LOOPBACK_DISCOVERY,
        )
    return _CONFIG.format(iface=iface, multicast="", general="", discovery="")


def init_dds(iface: str, domain_id: int = GO2_DOMAIN_ID) -> None:
    """Set up this process's DDS domain on ``iface``: once; again with the same settings is a
    no-op, with others a `QuaddanceError` (the SDK holds one domain per process)."""
    global _initialized
    if _initialized == (iface, domain_id):
        return
    if _initialized is not None:
        raise QuaddanceError(
            f"DDS is already set up on {_initialized[0]} (domain {_initialized[1]}) in this "
            f"process; cannot switch to {iface} (domain {domain_id})"
        )
    if not 0 <= domain_id <= 232:  # DDS's limit for its port mapping
        raise QuaddanceError(f"DDS domain id must be 0-232, got {domain_id}")
    config = cyclonedds_config(iface)
    load_sdk2()
    from unitree_sdk2py.core import channel

    # The SDK formats this template with the interface's name; ours has no placeholder.
    channel.ChannelConfigHasInterface = config
    try:
        channel.ChannelFactoryInitialize(domain_id, iface)
    except Exception as err:  # the SDK raises a bare Exception after printing Cyclone's reason
        raise QuaddanceError(
            f"cannot start DDS on network interface {iface} (domain {domain_id}): {err} "
            "(is the interface up? `ip link`)"
        ) from None
    _initialized = (iface, domain_id)


def polled_reader(topic: str, data_type: type, depth: int) -> Any:
    """A cyclonedds ``DataReader`` of ``topic`` in this process's domain (`init_dds` first)
    that keeps the newest ``depth`` samples until its owner takes them (``take(N)``, never
    blocking), on the owner's thread.

    Not the SDK's channels, whose readers call back from Cyclone's receive thread: Cyclone
    starts its threads at normal priority, and Python running there holds the GIL; on a busy
    machine the simulator's real-time loop waited for it up to 100 ms at a time.
    """
    global _participant
    if _initialized is None:
        raise RuntimeError("polled_reader before init_dds")
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.qos import Policy, Qos
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    if _participant is None:
        _participant = DomainParticipant(_initialized[1])
    return DataReader(
        _participant,
        Topic(_participant, topic, data_type),
        Qos(Policy.History.KeepLast(depth)),
    )


def take_serialized(reader: Any, n: int) -> list[bytes]:
    """Take up to ``n`` samples from a `polled_reader` as the bytes that arrived (with their
    encapsulation header), not deserialized: `DataReader.take` without its Python decoding,
    which costs ~0.3 ms a message (`quaddance.deploy.go2_wire` decodes with struct)."""
    from cyclonedds._clayer import ddspy_take
    from cyclonedds.core import DDSException, InstanceState, SampleState, ViewState

    taken = ddspy_take(reader._ref, SampleState.Any | ViewState.Any | InstanceState.Any, n)
    if isinstance(taken, int):  # an error code
        raise DDSException(taken, f"taking samples from {reader!r}")
    return [data for data, info in taken if info.valid_data]
