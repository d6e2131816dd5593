"""The study's model (the darr-niazi algorithm): its robot states, rule sets, rule, arbitration, tick kernel and
in-process engine (:class:`~swarm_ros.core.darr_niazi.engine.Simulation`), its metrics and summary, the invariants
``--check`` asserts, and the warm-up that fills numba's cache. What every algorithm shares stays in
:mod:`swarm_ros.core`."""
