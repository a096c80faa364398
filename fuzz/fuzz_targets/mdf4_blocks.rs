//! The MDF 4 block layer on arbitrary bytes: opening a file and walking what a reader walks
//! (the header, its data groups, their channel groups and channels, the channels'
//! compositions and names) never panics, never loops, and allocates only what the bounded
//! sizes allow; every refusal is an error naming a block and its offset.
#![no_main]

use std::io::Cursor;

use autoplug_logs::mdf4::blocks::MdfBlocks;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok((mut blocks, _)) = MdfBlocks::open(Cursor::new(data)) else {
        return;
    };
    let Ok(hd) = blocks.block(64, &[b"HD"]) else {
        return;
    };
    let Ok(groups) = blocks.chain(hd.link(0), 0, b"DG") else {
        return;
    };
    for dg in groups {
        let Ok(cgs) = blocks.chain(dg.link(1), 0, b"CG") else {
            continue;
        };
        for cg in cgs {
            let Ok(cns) = blocks.chain(cg.link(1), 0, b"CN") else {
                continue;
            };
            for cn in cns {
                let _ = blocks.chain(cn.link(1), 0, b"CN");
                let _ = blocks.block(cn.link(2), &[b"TX"]);
                let _ = blocks.header(cn.link(5), &[b"DT", b"SD", b"DZ", b"DL", b"HL"]);
            }
        }
        let _ = blocks.header(dg.link(2), &[b"DT", b"DZ", b"DL", b"HL"]);
    }
});
