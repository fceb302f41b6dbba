#!/usr/bin/env python3
"""obsbias.py MODEL_DIR TRUTH_DIR: triangulate each model track with the TRUE cameras (linear, then Gauss-Newton),
and tabulate the mean signed reprojection residual (observed - true projection) by row band and column band."""
import sys, math
def qrot(qw,qx,qy,qz):
    return [[1-2*(qy*qy+qz*qz),2*(qx*qy-qz*qw),2*(qx*qz+qy*qw)],
            [2*(qx*qy+qz*qw),1-2*(qx*qx+qz*qz),2*(qy*qz-qx*qw)],
            [2*(qx*qz-qy*qw),2*(qy*qz+qx*qw),1-2*(qx*qx+qy*qy)]]
def read_cams(d):
    cams={}
    for l in open(d+'/cameras.txt'):
        if l.startswith('#') or not l.strip(): continue
        t=l.split(); cams[int(t[0])]=[float(x) for x in t[4:]]
    return cams
def read_images(d, with_obs):
    ims={}; lines=[l for l in open(d+'/images.txt') if not l.startswith('#')]
    for i in range(0,len(lines),2):
        t=lines[i].split()
        if not t: continue
        q=[float(x) for x in t[1:5]]; tr=[float(x) for x in t[5:8]]
        obs=[]
        if with_obs:
            p=lines[i+1].split()
            for k in range(0,len(p),3):
                obs.append((float(p[k]),float(p[k+1]),int(p[k+2])))
        ims[t[9]]=(qrot(*q),tr,int(t[8]),obs)
    return ims
model,truth=sys.argv[1],sys.argv[2]
tc=read_cams(truth)[1]; fx,fy,cx,cy=tc[0],tc[1],tc[2],tc[3]
W=int(open(truth+'/cameras.txt').read().split('\n')[3].split()[2]); H=int(open(truth+'/cameras.txt').read().split('\n')[3].split()[3])
ti=read_images(truth,False); mi=read_images(model,True)
tracks={}
for name,(R,t,c,obs) in mi.items():
    for (u,v,pid) in obs:
        if pid<0: continue
        tracks.setdefault(pid,[]).append((name,u,v))
def proj(R,t,X):
    y=[sum(R[r][k]*X[k] for k in range(3))+t[r] for r in range(3)]
    return y
def solve3(A,b):
    import copy
    M=[A[i][:]+[b[i]] for i in range(3)]
    for c in range(3):
        p=max(range(c,3),key=lambda r:abs(M[r][c])); M[c],M[p]=M[p],M[c]
        if abs(M[c][c])<1e-300: return None
        for r in range(3):
            if r!=c:
                f=M[r][c]/M[c][c]
                for k in range(c,4): M[r][k]-=f*M[c][k]
    return [M[i][3]/M[i][i] for i in range(3)]
nb=6
rows=[[0,0.0,0.0] for _ in range(nb)]; cols=[[0,0.0,0.0] for _ in range(nb)]
grid=[[[0,0.0,0.0] for _ in range(3)] for _ in range(3)]
allr=[0,0.0,0.0,0.0,0.0]
for pid,tr in tracks.items():
    if len(tr)<3: continue
    # linear midpoint: minimise sum of squared distances to rays
    A=[[0.0]*3 for _ in range(3)]; b=[0.0]*3
    views=[]
    for (name,u,v) in tr:
        R,t,_,_=ti[name]
        C=[-sum(R[k][r]*t[k] for k in range(3)) for r in range(3)]
        dcam=[(u-cx)/fx,(v-cy)/fy,1.0]
        d=[sum(R[k][r]*dcam[k] for k in range(3)) for r in range(3)]
        n=math.sqrt(sum(x*x for x in d)); d=[x/n for x in d]
        for r in range(3):
            for s in range(3):
                A[r][s]+=(1.0 if r==s else 0.0)-d[r]*d[s]
            b[r]+=sum(((1.0 if r==s else 0.0)-d[r]*d[s])*C[s] for s in range(3))
        views.append((R,t,u,v))
    X=solve3(A,b)
    if X is None: continue
    # Gauss-Newton on reprojection error
    for it in range(5):
        JTJ=[[0.0]*3 for _ in range(3)]; JTr=[0.0]*3
        for (R,t,u,v) in views:
            y=proj(R,t,X)
            if y[2]<=0: break
            pu=fx*y[0]/y[2]+cx; pv=fy*y[1]/y[2]+cy
            ru=u-pu; rv=v-pv
            Ju=[fx*(R[0][k]/y[2]-y[0]*R[2][k]/y[2]**2) for k in range(3)]
            Jv=[fy*(R[1][k]/y[2]-y[1]*R[2][k]/y[2]**2) for k in range(3)]
            for r in range(3):
                JTr[r]+=Ju[r]*ru+Jv[r]*rv
                for s in range(3): JTJ[r][s]+=Ju[r]*Ju[s]+Jv[r]*Jv[s]
        dx=solve3(JTJ,JTr)
        if dx is None: break
        X=[X[k]+dx[k] for k in range(3)]
    res=[]
    for (R,t,u,v) in views:
        y=proj(R,t,X); pu=fx*y[0]/y[2]+cx; pv=fy*y[1]/y[2]+cy
        res.append((u,v,u-pu,v-pv))
    if max(math.hypot(a[2],a[3]) for a in res)>3: continue
    for (u,v,du,dv) in res:
        rb=min(nb-1,int(v/H*nb)); cb=min(nb-1,int(u/W*nb))
        for arr,k in ((rows,rb),(cols,cb)):
            arr[k][0]+=1; arr[k][1]+=du; arr[k][2]+=dv
        g=grid[min(2,int(v/H*3))][min(2,int(u/W*3))]; g[0]+=1; g[1]+=du; g[2]+=dv
        allr[0]+=1; allr[1]+=du; allr[2]+=dv; allr[3]+=du*du+dv*dv; allr[4]+=math.hypot(du,dv)
print("truth pp (%.2f, %.2f) f %.2f; %d obs, mean du %.4f dv %.4f rms %.4f mean %.4f"%(cx,cy,fx,allr[0],allr[1]/allr[0],allr[2]/allr[0],math.sqrt(allr[3]/allr[0]),allr[4]/allr[0]))
print("row band (v)      n    mean du   mean dv")
for k in range(nb):
    n,a,b2=rows[k]; print("%4d-%4d %8d %9.4f %9.4f"%(k*H//nb,(k+1)*H//nb,n,a/max(n,1),b2/max(n,1)))
print("col band (u)      n    mean du   mean dv")
for k in range(nb):
    n,a,b2=cols[k]; print("%4d-%4d %8d %9.4f %9.4f"%(k*W//nb,(k+1)*W//nb,n,a/max(n,1),b2/max(n,1)))
print("3x3 grid (du,dv):")
for r in range(3):
    print("  ".join("(%+.3f,%+.3f)"%(g[1]/max(g[0],1),g[2]/max(g[0],1)) for g in grid[r]))
