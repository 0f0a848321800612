/*
 * busload_table.c — prints the bus-load table of docs/protocol.md (Markdown) from
 * mw_busload_compute(), so the document shows what the library computes. The ctest
 * wire_busload_table_matches_docs fails if the document and this output differ.
 */
#include <stdio.h>

#include "mocap_wire/mw_busload.h"

static void cell(const mw_busload* b) {
    printf(" %u.%u %% %s |", b->load_permille / 10u, b->load_permille % 10u, b->fits ? "fits" : "**no**");
}

int main(void) {
    static const unsigned nodes[] = {1, 5, 10, 15, 17, 20, 30};
    static const unsigned rates[] = {50, 100, 200};
    static const mw_mode modes[] = {MW_MODE_RAW, MW_MODE_ATTITUDE};
    printf("| nodes | rate Hz | mode | frames/s | bit/s | 500 kbit/s | 1 Mbit/s |\n");
    printf("|---:|---:|---|---:|---:|---:|---:|\n");
    for (size_t m = 0; m < sizeof modes / sizeof modes[0]; ++m) {
        for (size_t r = 0; r < sizeof rates / sizeof rates[0]; ++r) {
            for (size_t n = 0; n < sizeof nodes / sizeof nodes[0]; ++n) {
                mw_busload_params p = {nodes[n], rates[r], modes[m], 500000u, 1u};
                mw_busload slow;
                mw_busload fast;
                if (mw_busload_compute(&p, &slow) != MW_OK) return 1;
                p.bitrate_bps = 1000000u;
                if (mw_busload_compute(&p, &fast) != MW_OK) return 1;
                printf("| %u | %u | %s | %u | %u |", nodes[n], rates[r], modes[m] == MW_MODE_RAW ? "raw" : "attitude",
                       fast.frames_per_s, fast.bits_per_s);
                cell(&slow);
                cell(&fast);
                printf("\n");
            }
        }
    }
    return 0;
}
