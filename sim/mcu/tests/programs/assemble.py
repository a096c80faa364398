#!/usr/bin/env python3
"""Assembles the instruction tests' programs with LLVM (llvm-mc, llvm-objcopy, llvm-objdump
for thumbv7em-none-eabihf) and rewrites the block between the PROGRAMS markers in
sim/mcu/tests/instructions.rs: each program as bytes with its listing beside them.

    python3 sim/mcu/tests/programs/assemble.py

Every program gets the same vector table: SP 0x2000_8000, reset at 0x42, handlers named
nmi, hardfault, memmanage, busfault, usagefault, svc_handler, pendsv, systick where the
program defines them, else `unexpected` (0x40, `b .`). The tests need no LLVM tools; only
changing a program does.
"""
import os
import re
import subprocess
import sys
import tempfile

WORK = tempfile.mkdtemp()

VEC = {2:'nmi',3:'hardfault',4:'memmanage',5:'busfault',6:'usagefault',11:'svc_handler',14:'pendsv',15:'systick'}
def build(name, body):
    labels = set(re.findall(r'^(\w+):', body, re.M))
    lines = ['.syntax unified', '.thumb', 'vectors:', '.word 0x20008000', '.word reset - vectors + 1']
    for n in range(2, 16):
        h = VEC.get(n)
        lines.append('.word %s - vectors + 1' % (h if h in labels else 'unexpected'))
    lines += ['unexpected:', 'b unexpected', 'reset:']
    src = '\n'.join(lines) + '\n' + body + '\n'
    open(WORK + '/in.s','w').write(src)
    subprocess.run(['llvm-mc','-triple=thumbv7em-none-eabihf','-mcpu=cortex-m4','-mattr=+vfp4d16sp','-filetype=obj',WORK + '/in.s','-o',WORK + '/o.o'], check=True)
    subprocess.run(['llvm-objcopy','-O','binary','-j','.text',WORK + '/o.o',WORK + '/o.bin'], check=True)
    dis = subprocess.run(['llvm-objdump','-d','--triple=thumbv7em-none-eabihf','--mcpu=cortex-m4',WORK + '/o.o'], capture_output=True, text=True).stdout
    data = open(WORK + '/o.bin','rb').read()
    out = ['/// ```text']
    skip = True
    for line in dis.splitlines():
        m = re.match(r'^\s+([0-9a-f]+):\s+((?:[0-9a-f]{2}[ \t])+)\s*(.*)$', line)
        if m:
            addr = int(m.group(1),16)
            if addr < 0x40: continue
            out.append('/// %04x: %s' % (addr, re.sub(r'\s+',' ',m.group(3)).strip()))
        m2 = re.match(r'^([0-9a-f]+) <(\w+)>:', line)
        if m2 and not m2.group(2).startswith('$'):
            out.append('/// %s:' % m2.group(2))
    out.append('/// ```')
    out.append('const %s: &[u8] = &[' % name.upper())
    for i in range(0, len(data), 16):
        out.append('    ' + ', '.join('0x%02x' % b for b in data[i:i+16]) + ',')
    out.append('];')
    return '\n'.join(out)


cases = []
def case(name, body): cases.append((name, body))

case('it_flags', '''
  movs r0, #0
  it eq
  addeq r0, r1, r2
  mrs r3, apsr
done: b done
''')

case('it_branch', '''
  cmp r0, #1
  ite ne
  movne r1, #10
  beq skip
  movs r2, #99
skip:
  movs r3, #7
done: b done
''')

case('pc_relative', '''
  nop
  adr r0, lit
  ldr r1, lit
  ldr.w r2, lit
  nop
  adr.w r4, back
back:
  ldr.w r3, back2
  b done
  .p2align 2
back2:
lit: .word 0xCAFEF00D
done: b done
''')

case('shifts', '''
  lsrs r0, r1, #32
  mrs r8, apsr
  movs r3, #0
  lsls r4, r1, r3
  mrs r9, apsr
  movs r3, #33
  lsrs r5, r1, r3
  mrs r10, apsr
  movs r3, #32
  rors.w r11, r1, r3
  mrs r12, apsr
  asrs r6, r1, #32
  movs r3, #0
  rrxs r7, r1
done: b done
''')

case('saturate', '''
  ssat r0, #8, r1
  usat r2, #8, r3, lsl #4
  mrs r4, apsr
  qadd r5, r6, r7
  qdsub r8, r9, r10
  ssat16 r11, #4, r12
done: b done
''')

case('dsp', '''
  umaal r0, r1, r2, r3
  uxtb16 r4, r5, ror #8
  pkhbt r6, r7, r8, lsl #16
  uxtab r9, r10, r11
  uqadd8 r12, r5, r5
  uqadd16 r2, r6, r6
  smlad r3, r5, r5, r10
done: b done
''')

case('multiple', '''
  ldm r0, {r0, r1}
  ldm r2!, {r3, r4}
  mov r5, sp
  push {r3, r4, lr}
  adr r6, target
  adds r6, #1
  str r6, [sp, #8]
  pop {r3, r4, pc}
  movs r7, #1
target:
  mov r8, sp
done: b done
''')

case('table_branch', '''
  tbb [pc, r0]
tbl:
  .byte (c0 - tbl) / 2
  .byte (c1 - tbl) / 2
c0:
  movs r1, #10
  b next
c1:
  movs r1, #20
next:
  tbh [pc, r2, lsl #1]
tbl2:
  .hword (d0 - tbl2) / 2
  .hword (d1 - tbl2) / 2
d0:
  movs r3, #30
  b done
d1:
  movs r3, #40
done: b done
''')

case('exception_return_forms', '''
  ldr r0, =0xE000ED20
  mov r1, #0x00F00000
  str r1, [r0]
  ldr r0, =0xE000ED04
  mov r1, #0x10000000
  str r1, [r0]
  dsb
  isb
  mov r8, r4
  ldr r0, =0x20004000
  msr psp, r0
  movs r0, #2
  msr control, r0
  isb
  ldr r0, =0xE000ED04
  str r1, [r0]
  isb
  mov r9, r4
  mov r10, sp
  mrs r11, msp
done: b done
pendsv:
  mov r4, lr
  svc #0
  bx lr
svc_handler:
  mov r7, lr
  bx lr
''')

case('lazy_fp', '''
  ldr r0, =0xE000ED88
  mov r1, #0x00F00000
  str r1, [r0]
  dsb
  isb
  vmov.f32 s0, #1.0
  vmov.f32 s15, #2.0
  ldr r0, =0xE000ED04
  mov r1, #0x10000000
  str r1, [r0]
  isb
  vmov r5, s0
  vmov r6, s15
  mrs r7, control
  mov r8, r4
done: b done
pendsv:
  mov r4, lr
  ldr r0, =0xE000EF34
  ldr r9, [r0]
  vmov.f32 s0, #3.0
  vmov.f32 s15, #4.0
  ldr r10, [r0]
  ldr r0, =0xE000EF38
  ldr r11, [r0]
  bx lr
''')

case('faults', '''
  ldr r0, =0x20000000
  movs r1, #7
  udf #1
  movs r2, #9
done: b done
hardfault:
  ldr r3, =0xE000ED28
  ldr r4, [r3]
  ldr r3, =0xE000ED2C
  ldr r5, [r3]
  ldr r6, [sp, #24]
  adds r6, #2
  str r6, [sp, #24]
  bx lr
''')

case('invalid_return', '''
  ldr r0, =0xE000ED04
  mov r1, #0x10000000
  str r1, [r0]
  isb
done: b done
pendsv:
  ldr r0, =0xFFFFFFF5
  bx r0
hardfault:
  ldr r3, =0xE000ED28
  ldr r4, [r3]
fault_done: b fault_done
''')

case('lockup', '''
  udf #2
done: b done
hardfault:
  udf #3
''')

case('divide', '''
  udiv r0, r1, r2
  sdiv r3, r4, r5
  sdiv r6, r7, r8
  ldr r9, =0xE000ED14
  ldr r10, [r9]
  orr r10, r10, #0x10
  str r10, [r9]
  udiv r11, r1, r2
done: b done
hardfault:
  ldr r9, =0xE000ED28
  ldr r12, [r9]
fault_done: b fault_done
''')

case('sleep', '''
  ldr r2, =0xE000ED10
  movs r3, #0x10
  str r3, [r2]
  sev
  wfe
  movs r0, #1
  wfe
  movs r1, #2
done: b done
''')

case('unmodelled', '''
  ldr r0, =0x40006400
  ldr r1, [r0]
done: b done
''')

case('exclusive', '''
  ldr r0, =0x20000000
  ldrex r1, [r0]
  adds r1, #1
  strex r2, r1, [r0]
  strex r3, r1, [r0]
  ldrex r4, [r0]
  clrex
  strex r5, r4, [r0]
done: b done
''')

case('fp_arith', '''
  ldr r0, =0xE000ED88
  mov r1, #0x00F00000
  str r1, [r0]
  isb
  vmov s0, r2
  vmov s1, r3
  vadd.f32 s2, s0, s1
  vmrs r4, fpscr
  vcmp.f32 s0, s1
  vmrs APSR_nzcv, fpscr
  mrs r5, apsr
  vcvt.s32.f32 s3, s1
  vmov r6, s3
  vcvtr.s32.f32 s4, s1
  vmov r7, s4
  vmov r8, s2
  vsqrt.f32 s5, s0
  vmov r9, s5
  vdiv.f32 s6, s0, s1
  vmov r10, s6
  vfma.f32 s7, s0, s1
  vmov r11, s7
done: b done
''')



def main():
    path = os.path.join(os.path.dirname(__file__), '..', 'instructions.rs')
    text = open(path).read()
    begin = text.index('// BEGIN PROGRAMS')
    end = text.index('// END PROGRAMS')
    body = '\n\n'.join(build(name, src) for name, src in cases)
    text = text[:begin] + '// BEGIN PROGRAMS (generated by tests/programs/assemble.py)\n\n' + body + '\n\n' + text[end:]
    open(path, 'w').write(text)

if __name__ == '__main__':
    main()
