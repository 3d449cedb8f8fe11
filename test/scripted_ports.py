"""Test-only node ports: nothing arrives by itself; the test hands the node each input and keeps its frames.

Shared by the node tests that drive an EMAC node in process on a scripted clock (`test_emac_node_time.py`,
`test_emac_node_streams.py`).
"""

from types import SimpleNamespace

from ema_msgs_py import contract as ct


class ScriptedPorts:
    """The node's ports with the graph scripted: ``take`` holds each subscription's callback, ``sent`` each
    topic's published frames; ``publishers`` says how many publishers a topic has (``alive`` per topic, 1
    otherwise)."""

    composed = False

    def __init__(self, node, alive=None):
        self.node = node
        self.alive = dict(alive or {})
        self.take = {}
        self.sent = {}

    def frame_publisher(self, topic):
        return SimpleNamespace(publish=self.sent.setdefault(topic, []).append)

    def frame_subscription(self, topic, callback, on_bad, *, at_frame=False):  # noqa: ARG002
        self.take[topic] = callback

    def take_at_frame(self):
        """Inputs taken at the frame are handed over by the test as it scripts them: none waits here."""
        return 0

    def clock_subscription(self, callback):
        self.take[ct.CLOCK_TOPIC] = callback

    def publishers(self, topic):
        return self.alive.get(topic, 1)

    def endpoint_nodes(self):
        return [self.node]
