# summary.py CSV...: per scene, each integrator's relMSE (corrected where the reference has a variance image)
# and MSE at the last checkpoint, and U20 / mlt ratios.
import csv, sys
for f in sys.argv[1:]:
    rows = list(csv.DictReader(open(f)))
    last = {}
    for r in rows:
        last[r['integrator']] = r
    out = []
    for name, r in last.items():
        rel = float(r.get('rel_mse_corrected') or r['rel_mse'])
        mse = float(r.get('mse_corrected') or float(r['rmse'])**2)
        out.append((name, rel, mse, float(r['seconds'])))
    print(f)
    for n, rel, mse, s in out:
        print(f"  {n[:60]:60s} t={s:5.1f} relMSE={rel:.4g} MSE={mse:.4g}")
    base = [o for o in out if o[0] == 'mlt']
    for o in out:
        if o[0] != 'mlt' and base:
            print(f"  ratio {o[0][:40]}/mlt: relMSE {o[1]/base[0][1]:.3f}  MSE {o[2]/base[0][2]:.3f}")
