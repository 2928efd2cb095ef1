"""How the raw student's observation normalisation treats later rounds (issue 51 item 4).

Fits the refit's statistics (mean, sample deviation + 1e-8) to rounds 0-7 of a raw DAgger run,
as the round-7 refit did, and counts how often rounds 8-11 saturate the +-5 clip per block.
Needs numpy: .venv-interop/bin/python lab/results/raw-student/norm_stats.py runs/raw-student-s1
"""
import numpy as np, struct, sys
def read(p):
    b=open(p,'rb').read()
    od,ad,n=struct.unpack('<QQQ',b[8:32])
    f=np.frombuffer(b[32:],dtype='<f4')
    return f[:n*od].reshape(n,od), f[n*od:].reshape(n,ad)
run=sys.argv[1]
obs=[]; 
for r in range(12):
    o,a=read(f'{run}/rounds/round-{r:03d}.bin'); obs.append(o)
# stats as DAgger's refit at round 7 (rounds 0-7) applied to rounds 8..11
fit=np.concatenate(obs[:8]).astype(np.float64)
m=fit.mean(0); sd=fit.std(0,ddof=1)
scale=1/(sd+1e-8)
print('dims',fit.shape[1],'std<1e-6:',(sd<1e-6).sum(),'std<1e-4:',(sd<1e-4).sum(),'std<1e-3:',(sd<1e-3).sum())
blocks={'rgb':(0,768),'depth':(768,1024),'wrench':(1024,1216),'proprio':(1216,1224)}
for name,(a,b) in blocks.items():
    print(name,'min sd %.2e median sd %.2e'%(sd[a:b].min(),np.median(sd[a:b])))
for r in range(8,12):
    x=(obs[r].astype(np.float64)-m)*scale
    sat=(np.abs(x)>=5).mean(0)
    print('round',r,'share of values clipped at 5:',round(float((np.abs(x)>=5).mean()),4),
          'components clipped in >10% of samples:',int((sat>0.1).sum()),
          {n:int((sat[a:b]>0.1).sum()) for n,(a,b) in blocks.items()})
x=(fit-m)*scale
print('within the fitted rounds, share clipped:', round(float((np.abs(x)>=5).mean()),4))
