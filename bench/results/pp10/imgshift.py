import sys, zlib, struct
def readpng(p):
    d=open(p,'rb').read(); i=8; idat=b''; 
    while i<len(d):
        n=struct.unpack('>I',d[i:i+4])[0]; t=d[i+4:i+8]; c=d[i+8:i+8+n]
        if t==b'IHDR': w,h,bd,ct=struct.unpack('>IIBB',c[:10])
        if t==b'IDAT': idat+=c
        i+=12+n
    raw=zlib.decompress(idat); bpp={2:3,0:1,6:4}[ct]; stride=w*bpp; out=bytearray(); prev=bytearray(stride); k=0
    for y in range(h):
        f=raw[k]; k+=1; line=bytearray(raw[k:k+stride]); k+=stride
        for x in range(stride):
            a=line[x-bpp] if x>=bpp else 0; b=prev[x]; c2=prev[x-bpp] if x>=bpp else 0
            if f==1: line[x]=(line[x]+a)&255
            elif f==2: line[x]=(line[x]+b)&255
            elif f==3: line[x]=(line[x]+(a+b)//2)&255
            elif f==4:
                p=a+b-c2; pa=abs(p-a); pb=abs(p-b); pc=abs(p-c2)
                pr=a if pa<=pb and pa<=pc else (b if pb<=pc else c2); line[x]=(line[x]+pr)&255
        out+=line; prev=line
    return w,h,bpp,out
w,h,bpp,A=readpng(sys.argv[1]); _,_,_,B=readpng(sys.argv[2]); du,dv=int(sys.argv[3]),int(sys.argv[4])
# B(x,y) should equal A(x-du, y-dv)
best=None
for sx in range(du-2,du+3):
  for sy in range(dv-2,dv+3):
    s=0;n=0
    for y in range(40,h-40,3):
        for x in range(40,w-40,3):
            xa=x-sx; ya=y-sy
            s+=abs(B[(y*w+x)*bpp]-A[(ya*w+xa)*bpp]); n+=1
    print(sx,sy,round(s/n,3))
