"""Nodes of a site on the bus: detector, tracker and outputs nodes, and the local site
launcher (``optrack run``). See docs/runtime.md."""
