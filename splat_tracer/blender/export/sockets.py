"""What the node-tree readers (shading.py, nodes.py, world.py) share about sockets."""
from __future__ import annotations


def fmt(value) -> str:
    """A socket value as the report shows it: 3 significant digits, RGB only."""
    if isinstance(value, (int, float)):
        return f"{value:.3g}"
    return "(" + ", ".join(f"{v:.3g}" for v in tuple(value)[:3]) + ")"


def live_link(socket):
    """The link feeding an input socket, ignoring muted and invalid links."""
    return next((link for link in socket.links if link.is_valid and not link.is_muted), None)
