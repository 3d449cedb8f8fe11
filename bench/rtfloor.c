/* The machine's real-time floor: what any program gets here with the node suite's frame timing.
 *
 * A loop that sleeps to absolute deadlines every period and then works for a fixed CPU time, as the
 * suite's one thread does each 200 Hz frame (about 0.5 ms of work), at SCHED_FIFO, with memory locked and,
 * optionally, a PM QoS CPU latency request held as the suite's real-time set-up does. A frame is missed
 * when its work window (wake-up to work done) exceeds the period: the work itself is always the same,
 * so every miss is time the machine did not give the thread.
 *
 * usage: rtfloor DURATION_S PRIORITY PERIOD_MS WORK_MS CPU_LATENCY_US   (CPU_LATENCY_US < 0: none held)
 * prints one JSON line.
 */
#define _GNU_SOURCE
#include <fcntl.h>
#include <sched.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

static double mono(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static double thread_cpu(void) {
    struct timespec t;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

int main(int argc, char **argv) {
    if (argc != 6) {
        fprintf(stderr, "usage: rtfloor DURATION_S PRIORITY PERIOD_MS WORK_MS CPU_LATENCY_US\n");
        return 2;
    }
    double duration = atof(argv[1]), period = atof(argv[3]) * 1e-3, work = atof(argv[4]) * 1e-3;
    int priority = atoi(argv[2]), latency = atoi(argv[5]);
    int fifo = 0, locked = 0, held = 0;
    if (priority > 0) {
        struct sched_param p = {.sched_priority = priority};
        fifo = sched_setscheduler(0, SCHED_FIFO, &p) == 0;
    }
    locked = mlockall(MCL_CURRENT | MCL_FUTURE) == 0;
    if (latency >= 0) {
        int fd = open("/dev/cpu_dma_latency", O_WRONLY);
        int32_t value = latency;
        held = fd >= 0 && write(fd, &value, sizeof value) == (ssize_t)sizeof value; /* held until exit */
    }
    long frames = 0, missed = 0, missed_off_cpu = 0, late_wakeups = 0;
    double worst = 0.0, start = mono();
    volatile uint64_t sink = 0;
    for (;;) {
        frames++;
        double due = start + (double)frames * period;
        struct timespec ts = {.tv_sec = (time_t)due, .tv_nsec = (long)((due - (double)(time_t)due) * 1e9)};
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL);
        double woke = mono(), cpu0 = thread_cpu();
        while (thread_cpu() - cpu0 < work) sink++;
        double window = mono() - woke, cpu = thread_cpu() - cpu0;
        if (woke - due > period) late_wakeups++;
        if (window > period) {
            missed++;
            if (cpu <= period) missed_off_cpu++;
        }
        if (window > worst) worst = window;
        if (woke - start >= duration) break;
    }
    printf("{\"frames\": %ld, \"missed\": %ld, \"missed_off_cpu\": %ld, \"max_window_ms\": %.3f, "
           "\"late_wakeups\": %ld, \"sched_fifo\": %d, \"memory_locked\": %d, \"cpu_latency_held\": %d}\n",
           frames, missed, missed_off_cpu, worst * 1e3, late_wakeups, fifo ? priority : 0, locked, held);
    return 0;
}
