"""Scores session 28's alpha study (docs/smcmc.md): run in the OUT directory of
smcmc_alpha_s28.sh; prints each alpha's ratio to alpha 0.05, seed by seed, as a geometric
mean with a Student-t 95% interval on the log ratios (K - 1 dof)."""
import json,glob,math,re,collections,sys
from statistics import mean,stdev
d=collections.defaultdict(dict)
for f in glob.glob('*.cmp.json'):
    m=re.match(r'(\w+)-(\w+)-a([\d.]+)-s(\d+)\.cmp\.json',f)
    key,sh,a,s=m.groups()
    d[(key,sh,a)][int(s)]=json.load(open(f))['corrected']['rel_mse']
T={1:12.71,2:4.30,3:3.18,4:2.78,5:2.57,6:2.45,7:2.36,8:2.31,9:2.26,10:2.23,11:2.20,12:2.18,15:2.13,19:2.09}
for (key,sh,a) in sorted(d):
    if a=='0.05': continue
    base=d[(key,sh,'0.05')]; cur=d[(key,sh,a)]
    seeds=sorted(set(base)&set(cur))
    lr=[math.log(cur[s]/base[s]) for s in seeds]
    n=len(lr); m=mean(lr); se=stdev(lr)/math.sqrt(n) if n>1 else float('nan')
    t=T.get(n-1,2.1)
    print(f"{key} {sh} alpha {a} vs 0.05: n={n} geo-mean ratio {math.exp(m):.3f} [{math.exp(m-t*se):.3f}, {math.exp(m+t*se):.3f}]  mean relMSE {mean(cur.values()):.5f} vs {mean(base[s] for s in seeds):.5f}")
