"""Lifelong household maps: a log run as a new session of a map store (``holoslam.store``), relocalised against
it from an unknown start (``holoslam.relocalise``), joined into one graph and solved again (``joint``), its
objects compared with the store's (``changes``), and the store's merged map, trajectories and object history
exported (``export``). ``holoslam.lifelong.session.run_session`` is the one library call behind
``holoslam run LOG --map STORE``."""
