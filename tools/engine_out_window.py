#!/usr/bin/env python3
# usage: oils run --link inproc --log nom.oilslog && oils export nom.oilslog --csv nom.csv
#        tools/engine_out_window.py nom.csv 0 200 300 400     (failure times, seconds)
"""Engine out before 525 s: the best pitch programme found for the remaining pair.
Planar point mass about the Moon, the pair at full thrust (1600 N, Isp 310 s) from the
failure on, pitch (thrust angle above the local horizontal, against the motion) linear
between N nodes spread over the burn; Nelder-Mead (hand-written: no numpy here) from
several starts. Score: propellant left at touchdown after the cheapest vertical landing from where
the horizontal speed reaches zero (>= 0: landable), else a negative shortfall (kg above
the pair's hover mass, m/s over the touchdown limit, horizontal m/s left)."""
import csv, math, random, sys
MU=4.9048695e12; R=1737400.0; F=1600.0; VE=310.0*9.80665; MDOT=F/VE; MDRY=750.0
N=6
def landing_margin(m,h,w):
    """The cheapest vertical landing from height h descending at w (>0 down): coast,
    then the pair at full thrust straight up from the height where it just stops at the
    ground (a suicide burn). Propellant left (kg, >= 0: lands at <= 2 m/s), or a negative
    margin: minus the kilograms above the pair's hover mass, or minus the propellant
    short / the touchdown speed over 2 m/s."""
    dt=0.2
    g=MU/(R+h)**2
    if F/m-g<=0: return -(m-F/g)
    while True:
        g=MU/(R+h)**2; a=F/m-g
        if w>0 and w*w/(2*a)>=h: break
        w+=g*dt; h-=w*dt
        if h<=0: return -w
    while w>0:
        g=MU/(R+h)**2; a=F/m-g
        w-=a*dt; h-=w*dt; m-=MDOT*dt
        if m<=MDRY: return -w
        if h<=0: return (m-MDRY) if w<=2.0 else -(w-2.0)
    return m-MDRY
def fly(p, s0):
    m,h,vr,vt=s0; r=R+h; tb=(m-MDRY)/MDOT; dt=1.0; t=0.0
    while True:
        x=min(t/tb,1.0)*(N-1); i=min(int(x),N-2); f=x-i
        phi=p[i]*(1-f)+p[i+1]*f
        a=F/m
        dvr=vt*vt/r-MU/(r*r)+a*math.sin(phi)
        dvt=-vr*vt/r-a*math.cos(phi)
        vr+=dvr*dt; vt+=dvt*dt; r+=vr*dt; m-=MDOT*dt; t+=dt
        if r<=R: return -max(vt,0.0)-1000.0
        if vt<=0:
            return landing_margin(m,r-R,-vr)
        if m<=MDRY: return -vt
def nelder(fn,x0,step,iters):
    n=len(x0); pts=[x0]+[[x0[j]+(step if j==i else 0) for j in range(n)] for i in range(n)]
    vals=[fn(p) for p in pts]
    for _ in range(iters):
        order=sorted(range(n+1),key=lambda k:-vals[k]); pts=[pts[k] for k in order]; vals=[vals[k] for k in order]
        c=[sum(pts[k][j] for k in range(n))/n for j in range(n)]
        xr=[c[j]+(c[j]-pts[-1][j]) for j in range(n)]; fr=fn(xr)
        if fr>vals[0]:
            xe=[c[j]+2*(c[j]-pts[-1][j]) for j in range(n)]; fe=fn(xe)
            pts[-1],vals[-1]=(xe,fe) if fe>fr else (xr,fr)
        elif fr>vals[-2]: pts[-1],vals[-1]=xr,fr
        else:
            xc=[c[j]+0.5*(pts[-1][j]-c[j]) for j in range(n)]; fc=fn(xc)
            if fc>vals[-1]: pts[-1],vals[-1]=xc,fc
            else:
                pts=[pts[0]]+[[pts[0][j]+0.5*(p[j]-pts[0][j]) for j in range(n)] for p in pts[1:]]
                vals=[vals[0]]+[fn(p) for p in pts[1:]]
    k=max(range(n+1),key=lambda k:vals[k]); return pts[k],vals[k]
rows={}
f=open(sys.argv[1]); rd=csv.reader(f); hd=next(rd); ix={n:i for i,n in enumerate(hd)}
for k,row in enumerate(rd):
    if k%100: continue
    t=round(float(row[ix['telemetry.header.t_ns']])/1e9)
    rows[t]=(float(row[ix['truth.mass_kg']]),float(row[ix['truth.altitude_m']]),float(row[ix['truth.vertical_speed_m_s']]),float(row[ix['truth.horizontal_speed_m_s']]))
random.seed(1)
for tf in [int(a) for a in sys.argv[2:]]:
    s0=rows[tf]; best=(None,-1e9)
    for start in range(12):
        x0=[random.uniform(-0.3,1.2) for _ in range(N)]
        p,v=nelder(lambda p:fly(p,s0),x0,0.2,400)
        if v>best[1]: best=(p,v)
    p,v=best
    print("t_f %4d s: best score %8.1f (%s); pitch nodes deg %s"%(tf,v,"landable: kg of propellant left at touchdown" if v>=0 else "not found landable",[round(math.degrees(a)) for a in p]),flush=True)
