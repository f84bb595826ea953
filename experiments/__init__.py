"""Experiments: the runs behind the numbers of the spec pages and the README that are not speed (benchmarks/) and
not tests (tests/). Each module runs from the repository root as ``python -m experiments.<name> ...`` and writes
its files into ``experiments/results/<name>/`` (or where its ``--out`` says).

* :mod:`experiments.acrnn_table1` (+ :mod:`experiments.acrnn_eval`) — the dual-quaternion paper's Table 1 with
  acRNN (spec/acrnn.md §9);
* :mod:`experiments.quaternet_dq` — short-term QuaterNet, quaternions against dual quaternions (spec/quaternet.md);
* :mod:`experiments.quaternet_long_dq` — the long-term QuaterNet with dual quaternions (spec/locomotion.md);
* :mod:`experiments.bvh_fk_check` — every shared BVH file through the reader and FK against the independent oracle
  ``tests/bvh_oracle.py`` (spec/data.md).
"""
