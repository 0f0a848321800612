// mocap-bvh-repair — makes a BVH file that a crash or kill left behind loadable again:
// counts the complete MOTION lines, cuts a partial last line and rewrites "Frames:".
//
//   mocap-bvh-repair FILE.bvh...
//
// Prints "FILE: N frames (header said M, cut B bytes)" per file. Exit 0 if every file
// was repaired (or already right), 1 otherwise.
#include <cstdio>

#include "serve/bvh_recorder.hpp"

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: mocap-bvh-repair FILE.bvh...\n");
        return 1;
    }
    int status = 0;
    for (int i = 1; i < argc; ++i) {
        const auto r = mocap::serve::repair_bvh_file(argv[i]);
        if (!r.ok) {
            std::fprintf(stderr, "mocap-bvh-repair: %s\n", r.error.c_str());
            status = 1;
            continue;
        }
        std::printf("%s: %llu frames (header said %llu, cut %llu bytes)\n", argv[i],
                    static_cast<unsigned long long>(r.frames), static_cast<unsigned long long>(r.frames_before),
                    static_cast<unsigned long long>(r.bytes_cut));
    }
    return status;
}
