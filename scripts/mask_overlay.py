#!/usr/bin/env python3
"""Overlay of one object's tracked mask (SCENE/semantics/FRAME.png) against its ground truth
(SCENE/masks/FRAME.png) on the frame, cropped and enlarged 3x: green where both agree, red
where the tracker missed the object, blue where it took in something else. Made the figure
docs/img/track_sedan_frame35.png; standard library only.

    python3 scripts/mask_overlay.py SCENE ID FRAME OUT.png X0 Y0 X1 Y1
"""
import sys, zlib, struct
sys.path.insert(0, str(__import__('pathlib').Path(__file__).parent))
from gt_clicks import read_png_gray
from pathlib import Path
def read_rgb(path):
    """8-bit RGB/RGBA PNG -> (w, h, channels, rows)."""
    data=Path(path).read_bytes(); pos=8; idat=b''
    while pos<len(data):
        (n,)=struct.unpack('>I',data[pos:pos+4]); kind=data[pos+4:pos+8]; body=data[pos+8:pos+8+n]
        if kind==b'IHDR': w,h,depth,ctype=struct.unpack('>IIBB',body[:10]); ch={0:1,2:3,6:4}[ctype]
        elif kind==b'IDAT': idat+=body
        pos+=12+n
    raw=zlib.decompress(idat); stride=w*ch; rows=[]; prev=bytearray(stride)
    for y in range(h):
        f=raw[y*(stride+1)]; line=bytearray(raw[y*(stride+1)+1:(y+1)*(stride+1)])
        for i in range(stride):
            a=line[i-ch] if i>=ch else 0; b=prev[i]; c=prev[i-ch] if i>=ch else 0
            if f==1: line[i]=(line[i]+a)&255
            elif f==2: line[i]=(line[i]+b)&255
            elif f==3: line[i]=(line[i]+(a+b)//2)&255
            elif f==4:
                p=a+b-c; pa,pb,pc=abs(p-a),abs(p-b),abs(p-c); line[i]=(line[i]+(a if pa<=pb and pa<=pc else b if pb<=pc else c))&255
        rows.append(bytes(line)); prev=line
    return w,h,ch,rows
def write_png(path,w,h,pix):
    raw=b''.join(b'\x00'+bytes(r) for r in pix)
    def chunk(k,d): return struct.pack('>I',len(d))+k+d+struct.pack('>I',zlib.crc32(k+d)&0xffffffff)
    Path(path).write_bytes(b'\x89PNG\r\n\x1a\n'+chunk(b'IHDR',struct.pack('>IIBBBBB',w,h,8,2,0,0,0))+chunk(b'IDAT',zlib.compress(raw))+chunk(b'IEND',b''))
if __name__=="__main__":
    scene,oid,f,out,x0,y0,x1,y1=sys.argv[1],int(sys.argv[2]),sys.argv[3],sys.argv[4],*map(int,sys.argv[5:9])
    w,h,ch,img=read_rgb(f'{scene}/{f}.png'); _,_,a=read_png_gray(f'{scene}/semantics/{f}.png'); _,_,b=read_png_gray(f'{scene}/masks/{f}.png')
    S=3; pix=[]
    for y in range(y0,y1):
        row=[]
        for x in range(x0,x1):
            r,g,bb=img[y][x*ch:x*ch+3]; A=a[y][x]==oid; B=b[y][x]==oid
            if A and not B: r,g,bb=0,0,255
            elif B and not A: r,g,bb=255,0,0
            elif A and B: r,g,bb=(r+0)//2,(g+255)//2,bb//2
            row+= [r,g,bb]*S
        for _ in range(S): pix.append(row)
    write_png(out,(x1-x0)*S,(y1-y0)*S,pix)
