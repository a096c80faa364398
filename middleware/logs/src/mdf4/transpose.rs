//! MDF's transposed deflate (`##DZ` zip type 1) keeps a block's records column by column:
//! every record's byte 0, then every record's byte 1, and so on (what does not fill a whole
//! record stays as it was, at the end). Records of bus logging repeat themselves byte for
//! byte in the same column, which is why it deflates smaller.
//!
//! The simple double loop walks one side of the buffer a whole record apart at every
//! byte: on a 1 MiB block that is a cache miss a byte, and it took a third of a compressed
//! file's reading (perf, `scripts/mf4-benchmark`). Here the rows go in tiles small enough
//! that a tile's records stay in L1 while each column's run of the tile is read (or
//! written) in order.

/// Rows per tile: a tile of records of up to 128 bytes stays within a 32 KiB L1 cache.
const TILE: usize = 256;

/// Column-major `columns`-byte records back to rows (`transposed` as a DZ block inflates
/// to); bytes past the last whole record are copied as they are.
pub fn rows_from_columns(transposed: &[u8], columns: usize) -> Vec<u8> {
    let mut rows = vec![0u8; transposed.len()];
    if columns == 0 {
        rows.copy_from_slice(transposed);
        return rows;
    }
    let n = transposed.len() / columns;
    for start in (0..n).step_by(TILE) {
        let tile = TILE.min(n - start);
        let out = &mut rows[start * columns..(start + tile) * columns];
        for c in 0..columns {
            let column = &transposed[c * n + start..c * n + start + tile];
            // The rows start as zeros, and many columns are zero throughout (the data
            // bytes a classic frame leaves unused in a record sized for CAN FD's 64):
            // those are passed over (an OR over the run, which vectorises).
            if column.iter().fold(0, |any, &b| any | b) == 0 {
                continue;
            }
            for (record, &byte) in out.chunks_exact_mut(columns).zip(column) {
                record[c] = byte;
            }
        }
    }
    rows[n * columns..].copy_from_slice(&transposed[n * columns..]);
    rows
}

/// Records of `columns` bytes laid out column by column (the inverse of
/// [`rows_from_columns`]).
pub fn columns_from_rows(records: &[u8], columns: usize) -> Vec<u8> {
    let mut out = vec![0u8; records.len()];
    if columns == 0 {
        out.copy_from_slice(records);
        return out;
    }
    let n = records.len() / columns;
    for start in (0..n).step_by(TILE) {
        let tile = TILE.min(n - start);
        let block = &records[start * columns..(start + tile) * columns];
        for c in 0..columns {
            let column = &mut out[c * n + start..c * n + start + tile];
            for (byte, record) in column.iter_mut().zip(block.chunks_exact(columns)) {
                *byte = record[c];
            }
        }
    }
    out[n * columns..].copy_from_slice(&records[n * columns..]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The plain definition, one byte at a time.
    fn naive(records: &[u8], columns: usize) -> Vec<u8> {
        let n = records.len() / columns;
        let mut out = records.to_vec();
        for r in 0..n {
            for c in 0..columns {
                out[c * n + r] = records[r * columns + c];
            }
        }
        out
    }

    #[test]
    fn tiles_give_what_the_definition_gives_and_come_back() {
        // Row counts below, at and across a tile's edge, and a tail short of a record.
        for columns in [1, 3, 8, 84, 131] {
            for rows in [0, 1, 5, TILE - 1, TILE, TILE + 1, 3 * TILE + 7] {
                for tail in [0, columns / 2] {
                    let records: Vec<u8> = (0..rows * columns + tail)
                        .map(|i| (i * 7 + i / 251) as u8)
                        .collect();
                    let columns_first = columns_from_rows(&records, columns);
                    assert_eq!(
                        columns_first,
                        naive(&records, columns),
                        "{columns} x {rows}"
                    );
                    assert_eq!(rows_from_columns(&columns_first, columns), records);
                }
            }
        }
    }
}
