"""Many photos at once: the batch engine on Dask's distributed scheduler, bench, check.

`batch` is the engine (a local cluster or a scheduler's address); `runs` each photo's
command and its resumable result; `checks` is `totems check DIR...` and its index;
`bench` is `totems bench` and the paper's tables.

May import: verify.report, verify.verdict, verify.metrics, inverse.fit, scenes,
scenes.synthetic.
"""
