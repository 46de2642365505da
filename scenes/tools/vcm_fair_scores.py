"""Scores session 27's fair `vcm` vs `mcmc-vcm` runs (docs/vcm.md,
"Session 27"): run in the study directory, which holds per seed S and tag T
(`vcm-l16`, `mcmc-vcm-l4`) `time-S-T.txt` (GNU time "%U %S %e"), the final
images' sidecars `img-S/NAME.json` and `mcmc-render compare --json` output
`cmp-S-T-{long,second,pooled}.json` (the three references of the docs).
Writes scores.csv and prints the per-seed MSE ratios with a Student-t
interval over seeds (K - 1 = 2 degrees of freedom).

Arguments (optional): the two tags, `vcm` first (default `vcm-l16
mcmc-vcm-l4`, session 27; session 28: `vcm-l16 mcmc-vcm-l16`); a tag
`NAME-lN` is the sidecar `NAME_light_subpaths_N`."""
import json, math, statistics as st, sys
rows=["seed,integrator,reference,plain_mse,corrected_mse,mse_floor,corrected_rel_mse,cpu_s,samples"]
names={"long":"long+var(14592)","second":"long x s21 (second reference)","pooled":"pooled+var(58368)"}
tags=sys.argv[1:3] if len(sys.argv) >= 3 else ["vcm-l16","mcmc-vcm-l4"]
I={t:"{}_light_subpaths_{}".format(*t.rsplit("-l",1)) for t in tags}
vcm_tag, mcmc_tag = tags
mse={}
for s in (31,32,33):
    for t in I:
        u,sy,_=open(f"time-{s}-{t}.txt").read().split()
        cpu=float(u)+float(sy)
        samples=json.load(open(f"img-{s}/{I[t]}.json"))["samples"]
        for m in names:
            j=json.load(open(f"cmp-{s}-{t}-{m}.json"))
            c=j["corrected"]
            mse[(s,t,m)]=c["mse"]
            rows.append(f"{s},{t},{names[m]},{j['rmse']**2:.6e},{c['mse']:.6e},{c['mse_floor']:.6e},{c['rel_mse']:.6e},{cpu:.1f},{samples}")
open("scores.csv","w").write("\n".join(rows)+"\n")
# t quantiles 0.975 for 2 dof
t2=4.303
for m in names:
    r=[mse[(s,vcm_tag,m)]/mse[(s,mcmc_tag,m)] for s in (31,32,33)]
    mean=st.mean(r); se=st.stdev(r)/math.sqrt(3)
    print(m, " ".join(f"{x:.2f}" for x in r), f"mean {mean:.2f} ± {se:.2f} (95% {mean-t2*se:.2f} – {mean+t2*se:.2f})")
for s in (31,32,33):
    print(s, " ".join(f"{t} {mse[(s,t,'second')]:.3e}" for t in I))
