#!/usr/bin/env python3
"""Reads mcmc-core/tests/npz/fit.npz with numpy (the arrays ArviZ's
`az.from_dict` takes) and prints, as JSON, what numpy sees: per array its
dtype, shape, the first and last element and the sum.

Usage: python3 mcmc-core/tests/npz/read_back.py > mcmc-core/tests/npz/expected.json
"""
import json, os
import numpy as np

here = os.path.dirname(os.path.abspath(__file__))
with np.load(os.path.join(here, "fit.npz")) as d:
    out = {
        "numpy": np.__version__,
        "arrays": {
            k: {
                "dtype": d[k].dtype.str,
                "shape": list(d[k].shape),
                "first": d[k][0, 0].item(),
                "last": d[k][-1, -1].item(),
                "sum": d[k].sum().item(),
            }
            for k in sorted(d.files)
        },
    }
print(json.dumps(out, indent=1))
