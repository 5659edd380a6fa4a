/* A fake haptic device behind the hapsim plugin ABI, built by the tests.
 * args: "" = a handle circling slowly in the xy plane; "nan" = the same, but
 * reads return NaN after the first 500; "garbage" = after 500 reads, every
 * other read fails with an error code and the rest return infinities and a
 * gripper of 1e300; "glitch" = reads 501, 502 and 503 are bad once each (a
 * NaN position, an error code, a NaN velocity), the rest good; "press" = the
 * tip waits 500 reads at (30, 20, 50) mm, moves down at 20 mm/s to z = 30 mm
 * and holds there; reads 3001-3004 are bad once each (a NaN position, an
 * error code, a NaN velocity, a NaN gripper); "block" = the
 * 500th read never returns; "fail-open" = open fails. */
#include "../../haptic-daemon/include/hapsim_device.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

typedef struct {
    int nan_mode;
    int garbage_mode;
    int glitch_mode;
    int press_mode;
    int block_mode;
    long reads;
    int enabled;
    double last_force[3];
} fake;

uint32_t hapsim_device_abi_version(void) { return HAPSIM_DEVICE_ABI_VERSION; }

int hapsim_device_open(void **handle, const char *args) {
    if (strcmp(args, "fail-open") == 0) return 7;
    fake *f = calloc(1, sizeof(fake));
    if (!f) return 1;
    f->nan_mode = strcmp(args, "nan") == 0;
    f->garbage_mode = strcmp(args, "garbage") == 0;
    f->glitch_mode = strcmp(args, "glitch") == 0;
    f->press_mode = strcmp(args, "press") == 0;
    f->block_mode = strcmp(args, "block") == 0;
    *handle = f;
    return 0;
}

int hapsim_device_specs(void *handle, hapsim_specs *out) {
    (void)handle;
    out->max_force_n = 3.3;
    out->max_stiffness_n_per_m = 1500.0;
    for (int i = 0; i < 3; i++) { out->workspace_min_m[i] = -0.1; out->workspace_max_m[i] = 0.1; }
    return 0;
}

int hapsim_device_enable(void *handle) { ((fake *)handle)->enabled = 1; return 0; }

int hapsim_device_read(void *handle, hapsim_state *out) {
    fake *f = handle;
    double t = f->reads++ * 1e-3;
    out->position_m[0] = 0.01 * cos(t);
    out->position_m[1] = 0.01 * sin(t);
    out->position_m[2] = 0.0;
    out->velocity_m_s[0] = -0.01 * sin(t);
    out->velocity_m_s[1] = 0.01 * cos(t);
    out->velocity_m_s[2] = 0.0;
    out->gripper = 1.0;
    out->buttons = 0;
    if (f->nan_mode && f->reads > 500) out->position_m[0] = NAN;
    if (f->block_mode && f->reads > 500) for (;;) pause();
    if (f->press_mode) {
        double z = 0.05 - 0.02 * (t - 0.5);
        if (t < 0.5) z = 0.05;
        if (z < 0.03) z = 0.03;
        out->position_m[0] = 0.03;
        out->position_m[1] = 0.02;
        out->position_m[2] = z;
        for (int i = 0; i < 3; i++) out->velocity_m_s[i] = 0.0;
        if (t >= 0.5 && z > 0.03) out->velocity_m_s[2] = -0.02;
        if (f->reads == 3001) out->position_m[2] = NAN;
        if (f->reads == 3002) return -42;
        if (f->reads == 3003) out->velocity_m_s[0] = NAN;
        if (f->reads == 3004) out->gripper = NAN;
    }
    if (f->glitch_mode && f->reads == 501) out->position_m[2] = NAN;
    if (f->glitch_mode && f->reads == 502) return -42;
    if (f->glitch_mode && f->reads == 503) out->velocity_m_s[0] = NAN;
    if (f->garbage_mode && f->reads > 500) {
        if (f->reads % 2) return -42;
        out->position_m[1] = INFINITY;
        out->velocity_m_s[2] = -INFINITY;
        out->gripper = 1e300;
    }
    return 0;
}

int hapsim_device_write_force(void *handle, const double force_n[3]) {
    fake *f = handle;
    memcpy(f->last_force, force_n, sizeof f->last_force);
    return 0;
}

void hapsim_device_disable(void *handle) { ((fake *)handle)->enabled = 0; }

void hapsim_device_close(void *handle) { free(handle); }
