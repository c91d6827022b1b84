"""The radio part: who hears whom. A "medium" is the one thing that carries the robots' frames,
chosen per run with --medium: `veth` (veth.py, bridges and veth links that the topology
controller switches) or `ns3-wifi` (ns3wifi.py, an 802.11 channel simulated by ns-3). The
range models that decide the link set (ranges.py) and their line-of-sight geometry (los.py)
serve both."""
