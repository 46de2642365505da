import csv,re,glob,sys
cpu={}
for log in glob.glob('docs/results/fused-s26/pre/q*.log'):
    for l in open(log):
        if 'load' in l: continue
        m=re.match(r'seed (\d+) (\S+)(?: (\S+))? ([\d.]+) user ([\d.]+) sys',l)
        if not m: continue
        s,a,b,u,sy=m.groups()
        if float(u)==0: continue
        if log.endswith('/q.log'): key=('gl',int(s),'fused' if a=='fused' else 'fused_path_space_probability_0.05')
        else: key=(a,int(s),b)
        cpu[key]=float(u)+float(sy)
def val(sc,s,tag):
    r=list(csv.DictReader(open(f'docs/results/fused-s26/pre/{sc}-s{s}-{tag}.csv')))[-1]
    return float(r['rel_mse_corrected']), cpu[(sc,s,tag)], int(r['samples'])
for sc,tags in [('door',['auto','pilotlazy','lazy','lens_perturbation0','lens_perturbation_2','lens_perturbation_3','lens_perturbation_5','lens_perturbation_9','fused+path_space_probability_0.2','mmlt']),('gl',['fused','fused_path_space_probability_0.05','pilotlazy','lens_perturbation_3'])]:
    for t in tags:
        try:
            v=[val(sc,s,t) for s in [10,11,12,13]]
        except Exception as e:
            continue
        x=[a*b for a,b,c in v]
        print(sc,t,'relMSE',' / '.join('%.3e'%a for a,b,c in v),'| x cpu',' / '.join('%.3f'%y for y in x),'mean %.4f'%(sum(x)/4),'| cpu',' '.join('%.1f'%b for a,b,c in v),'| mut',' '.join('%.1f'%(c/1e6) for a,b,c in v))
