#include "stages/ingest/ingest_stage.hpp"

#include <cstdlib>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

int main(int argc, char** argv)
{
#if defined(__GLIBC__)
    // The allocator's settings for this process, here only (the library's
    // phases call malloc_trim at their ends, which changes no setting).
    //
    // Ingest builds and drops many large arrays (hundreds of MB in all on
    // the 20-state tract set). By default glibc serves each from a fresh
    // mmap and unmaps it on free, so every one is page-faulted in again:
    // 1.0-1.4 s of system time there. Served from the heap and kept on
    // free, they are reused: system time -34 to -44%, wall time -11 to
    // -17%, peak memory +5 to +8% (BENCHMARKS.md, "Ingest").
    mallopt(M_MMAP_MAX, 0);
    mallopt(M_TRIM_THRESHOLD, 1 << 30);
    // One arena for every thread, so the levels' threads reuse what the
    // interning and the merge freed (tract set, peak RSS: 281-297 MiB with
    // glibc's default arenas, 244-248 MiB with one; time within the noise).
    // MALLOC_ARENA_MAX in the environment wins.
    if (std::getenv("MALLOC_ARENA_MAX") == nullptr) {
        mallopt(M_ARENA_MAX, 1);
    }
#endif
    return tigerlod::run_stage<tigerlod::ingest::IngestStage>(argc, argv);
}
