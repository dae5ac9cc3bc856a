"""Writes LiDAR packets as a packet capture with scapy (Ethernet, IPv4, UDP to one
port, each packet stamped with its time), as a sensor's packets are captured by
tcpdump or Wireshark: the input is what tests/pcap.rs extracts from a packet log,
records of {stamp u64 ns, length u32, the packet}, little-endian.

usage: python write_pcap.py PACKETS OUT.pcap PORT [--nanoseconds] [--vlan] [--pcapng]
"""
import struct
import sys
from decimal import Decimal

from scapy.all import IP, UDP, Dot1Q, Ether, Raw, wrpcap, wrpcapng


def main():
    source, out, port = sys.argv[1], sys.argv[2], int(sys.argv[3])
    nanoseconds = "--nanoseconds" in sys.argv[4:]
    vlan = "--vlan" in sys.argv[4:]
    data = open(source, "rb").read()
    frames, at = [], 0
    while at < len(data):
        stamp_ns, length = struct.unpack_from("<QI", data, at)
        at += 12
        link = Ether(src="60:76:88:00:00:01", dst="ff:ff:ff:ff:ff:ff")
        if vlan:
            link = link / Dot1Q(vlan=7)
        frame = link / IP(src="192.168.1.201", dst="192.168.1.77") / UDP(sport=port, dport=port) / Raw(data[at : at + length])
        frame.time = Decimal(stamp_ns) / Decimal(1_000_000_000)
        frames.append(frame)
        at += length
    if "--pcapng" in sys.argv[4:]:
        wrpcapng(out, frames)
    else:
        wrpcap(out, frames, nano=nanoseconds)
    print(len(frames), "packets")


if __name__ == "__main__":
    main()
