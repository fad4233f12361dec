/* Makes an LMMS render repeatable: loaded with LD_PRELOAD by `benchmarks/real_music.py`.
 *
 * LMMS seeds rand() from its pid and the clock, and mixes on one worker thread per CPU; two
 * renders of one project differ, and fixing the seed alone does not make them agree. Here the
 * seed is fixed, and LMMS is told that the machine has one CPU, so it mixes on one thread:
 * two builds then hold the same audio (benchmarks/results/real_music_lmms_repeat.json).
 *
 * Build: cc -shared -fPIC -O2 -o lmms_repeatable.so lmms_repeatable.c -ldl
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <unistd.h>

#define SEED 12345u

void srand(unsigned int seed) {
    (void)seed;
    void (*real)(unsigned int) = (void (*)(unsigned int))dlsym(RTLD_NEXT, "srand");
    real(SEED);
}

void srandom(unsigned int seed) {
    (void)seed;
    void (*real)(unsigned int) = (void (*)(unsigned int))dlsym(RTLD_NEXT, "srandom");
    real(SEED);
}

long sysconf(int name) {
    long (*real)(int) = (long (*)(int))dlsym(RTLD_NEXT, "sysconf");
    if (name == _SC_NPROCESSORS_ONLN || name == _SC_NPROCESSORS_CONF) return 1;
    return real(name);
}

int get_nprocs(void) { return 1; }

int get_nprocs_conf(void) { return 1; }
