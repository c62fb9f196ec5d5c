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


def upstream(socket):
    """(node, output socket) feeding an input, through reroutes and muted nodes (which pass
    their input on); None when nothing is connected."""
    link = live_link(socket)
    while link is not None:
        node = link.from_node
        if node.type == "REROUTE":
            link = live_link(node.inputs[0])
        elif node.mute:
            passed = next((l for l in node.internal_links if l.to_socket == link.from_socket), None)
            link = live_link(passed.from_socket) if passed is not None else None
        else:
            return node, link.from_socket
    return None
