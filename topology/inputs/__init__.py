"""The inputs part: what the outside world hands the topology, each read with care. Map
pictures (pngmap), movement traces (mobility) and the trace player that replays them
(player), and the live position feed (feed) with its line splitter (linebuffer)."""
