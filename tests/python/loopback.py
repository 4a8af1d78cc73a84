"""Cyclone DDS on the loopback interface for the peers in this folder: without it a Cyclone
participant that starts first took 7 s to match rpkm's RustDDS (platform-facts); with `lo`,
no multicast and 127.0.0.1 as peer, about 120 ms. Import this module before cyclonedds: the
configuration is read when the first DomainParticipant is created."""
import os

LOOPBACK_CONFIG = """<CycloneDDS><Domain id="any">
  <General><Interfaces><NetworkInterface name="lo"/></Interfaces>
    <AllowMulticast>false</AllowMulticast></General>
  <Discovery><Peers><Peer address="127.0.0.1"/></Peers>
    <ParticipantIndex>auto</ParticipantIndex>
    <MaxAutoParticipantIndex>60</MaxAutoParticipantIndex></Discovery>
</Domain></CycloneDDS>"""

os.environ.setdefault("CYCLONEDDS_URI", LOOPBACK_CONFIG)
