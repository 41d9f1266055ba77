"""Fixtures of the live tests: ROS 2 over Cyclone DDS on this machine alone."""

import os

import pytest


@pytest.fixture
def loopback(tmp_path, monkeypatch):
    """Cyclone DDS on the loopback interface only, in a domain of this test alone."""
    xml = tmp_path / "cyclonedds.xml"
    xml.write_text(
        "<CycloneDDS><Domain Id='any'><General><Interfaces><NetworkInterface name='lo'/>"
        "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
        "<ParticipantIndex>auto</ParticipantIndex><Peers><Peer Address='127.0.0.1'/></Peers>"
        "</Discovery></Domain></CycloneDDS>"
    )
    monkeypatch.setenv("CYCLONEDDS_URI", xml.as_uri())
    domain = 100 + os.getpid() % 100  # another pytest process picks another domain
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    return domain
