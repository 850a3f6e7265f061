"""The benchmark report (``taichi-frac bench report``), one module per part.

It lives in the checkout, not in the installed package: ``taichi-frac bench`` finds this
folder beside ``taichi_frac/`` and imports it. The scripts ``bench_*.py`` time single
stages from the command line.

- ``tables``: the paper's Table 1 (scene sizes, fragments) and Table 2 (ms per frame);
- ``grouping``: two-scale vs single-scale dynamics, boundary grouping n = 1, 2, 4, 8,
  time against the error each n costs;
- ``sph``: SPH stress error against particle count and time (plain, corrected gradient);
- ``scaling``: ms per frame and peak memory against physics particle count (1e3 .. 1e6);
- ``stability``: the hard cases of the dynamics and the fracture as a table;
- ``dynamics``: the ``bench dynamics`` table (the 13-ring scene two- vs single-scale,
  the drop error at n = 4 against n = 1, a fragment pile);
- ``contact``, ``contact_grouping``: its surface-contact page (docs/benchmarks/contact.md),
  every contact mode on the same bodies, against exact rest heights and rigid-body
  references (``tests/support/rigid_drop.py``: an event-driven drop onto a frictionless plane);
- ``report``: runs the parts and writes ``docs/benchmarks.md``, its plots and a summary.
- the bodies and impacts the report shares with the test suite are the suite's own
  (``tests/support/bodies.py``, ``fracture_ring.py``), so both describe the same set-ups.

Each part's ``run(ctx) -> Section`` measures, prints progress through ``ctx.progress`` and
returns its markdown (every number in it comes from the run) and the plots it wrote.
Nothing here is imported by the simulator; numpy per body is fine (STYLE.md habit 3).
"""
