"""QoS profiles and DDS configuration of the ROS 2 link.

The profiles are rclpy's (``rclpy.qos``) spelled for ``cyclonedds``: what a ROS 2 node
publishes with must be matched here, or DDS silently pairs no reader with the writer (a
reliable reader never hears a best-effort writer; a volatile writer never serves a
transient-local reader the last sample).

:func:`cyclone_config` is the ``CYCLONEDDS_URI`` XML: ``IgnoreTypeInformation`` makes Cyclone
match rmw's endpoints by type name (without it the topics are discovered but no data moves),
and ``loopback=True`` keeps the traffic on 127.0.0.1 with unicast discovery (tests, demos on
one machine). :func:`fastdds_profile` is the matching profile for rclpy peers (Fast DDS), and
:func:`loopback_env` the environment a test gives both processes.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = [
    "QOS",
    "qos",
    "cyclone_config",
    "fastdds_profile",
    "loopback_env",
]

#: name -> (reliable, transient_local, depth), after rclpy's presets.
QOS: dict[str, tuple[bool, bool, int]] = {
    # rclpy's default (``10``): reliable, volatile, keep last 10
    "default": (True, False, 10),
    # ``qos_profile_sensor_data``: best effort, volatile, keep last 5
    "sensor": (False, False, 5),
    # map_server's ``/map``, latched topics: reliable, transient local, keep last 1
    "latched": (True, True, 1),
    # readers of robot state: best effort matches reliable and best-effort writers, and a
    # late sample is not worth a retransmission (the next one is newer)
    "state": (False, False, 10),
}


def qos(name: str):
    """The ``cyclonedds.qos.Qos`` of profile ``name`` (:data:`QOS`)."""
    from cyclonedds.qos import Policy, Qos

    try:
        reliable, latched, depth = QOS[name]
    except KeyError:
        raise ValueError(f"ros2: unknown QoS profile {name!r} (have {sorted(QOS)})") from None
    policies = [
        Policy.Reliability.Reliable(max_blocking_time=100_000_000)
        if reliable
        else Policy.Reliability.BestEffort,
        Policy.Durability.TransientLocal if latched else Policy.Durability.Volatile,
        Policy.History.KeepLast(depth),
    ]
    return Qos(*policies)


def cyclone_config(*, loopback: bool = False, interface: str | None = None) -> str:
    """The Cyclone DDS configuration XML (for ``CYCLONEDDS_URI``).

    ``loopback``: only 127.0.0.1, no multicast, peers found by unicast on localhost.
    ``interface``: the network interface (name or address) to use on a real network.
    """
    general, discovery = "", ""
    if loopback:
        general = (
            '<Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>'
            "<AllowMulticast>false</AllowMulticast>"
        )
        discovery = (
            "<ParticipantIndex>auto</ParticipantIndex>"
            "<MaxAutoParticipantIndex>40</MaxAutoParticipantIndex>"
            '<Peers><Peer address="127.0.0.1"/></Peers>'
        )
    elif interface:
        general = f'<Interfaces><NetworkInterface name="{interface}"/></Interfaces>'
    return (
        '<?xml version="1.0" encoding="UTF-8" ?>'
        '<CycloneDDS xmlns="https://cdds.io/config"><Domain Id="any">'
        f"<General>{general}</General><Discovery>{discovery}</Discovery>"
        "<Compatibility><IgnoreTypeInformation>1.15</IgnoreTypeInformation></Compatibility>"
        "</Domain></CycloneDDS>"
    )


def fastdds_profile() -> str:
    """A Fast DDS (rclpy's rmw) profile XML that keeps a participant on 127.0.0.1 (UDP only:
    shared memory does not reach Cyclone)."""
    return """<?xml version="1.0" encoding="UTF-8" ?>
<dds xmlns="http://www.eprosima.com">
  <profiles>
    <transport_descriptors>
      <transport_descriptor>
        <transport_id>swarmpark_loopback_udp</transport_id>
        <type>UDPv4</type>
        <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>
      </transport_descriptor>
    </transport_descriptors>
    <participant profile_name="swarmpark_loopback" is_default_profile="true">
      <rtps>
        <userTransports><transport_id>swarmpark_loopback_udp</transport_id></userTransports>
        <useBuiltinTransports>false</useBuiltinTransports>
      </rtps>
    </participant>
  </profiles>
</dds>
"""


def loopback_env(domain_id: int, workdir: str | Path) -> dict[str, str]:
    """Environment for a swarmpark process and rclpy peers on one machine, loopback only:
    the domain, Cyclone's config, rclpy's discovery range and Fast DDS profile (written into
    ``workdir``)."""
    if not 0 <= int(domain_id) <= 232:
        raise ValueError(f"ros2: domain_id must be in 0..232 (got {domain_id})")
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    prof = workdir / "fastdds_loopback.xml"
    prof.write_text(fastdds_profile())
    env = dict(os.environ)
    env.update(
        ROS_DOMAIN_ID=str(int(domain_id)),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        RMW_IMPLEMENTATION="rmw_fastrtps_cpp",
        FASTDDS_DEFAULT_PROFILES_FILE=str(prof),
        CYCLONEDDS_URI=cyclone_config(loopback=True),
    )
    env.pop("FASTRTPS_DEFAULT_PROFILES_FILE", None)
    return env
