/*
 * hapsim device plugin ABI, version 1.
 *
 * A plugin is a shared library (.so) that wraps a haptic device SDK (OpenHaptics,
 * Force Dimension, a lab's own driver) in these C functions. Load it with
 *   haptic-daemon run --device plugin:/path/libmydevice.so[:ARGS]
 * ARGS (everything after the second ':') is passed to hapsim_device_open.
 *
 * Units: metres, newtons, seconds. Frame: the scene's frame (do the device-to-
 * scene transform inside the plugin).
 *
 * Threading and real time: open/specs/close are called from the daemon's main
 * thread; enable, read, write_force and disable are called from the real-time
 * thread at the haptic rate (1-10 kHz). read and write_force MUST NOT block,
 * allocate unboundedly or sleep: hand the work to the SDK's own servo thread
 * if it has one. Return 0 on success, any other value on failure. A failing
 * read, or one with a NaN or infinite field, is a bad read: the daemon holds
 * the last good pose and the force (one bad read, or a few ms of them, are
 * not felt) and counts it (device_bad_reads); bad reads for longer than
 * --max-reject-run-ms (20 ms) ramp the force to zero until reads are good.
 *
 * The daemon clamps, slew-limits and NaN-guards every force before
 * write_force; the plugin should still keep the SDK's own safety features on
 * (and zero the force in disable and close).
 */
#ifndef HAPSIM_DEVICE_H
#define HAPSIM_DEVICE_H

#include <stdint.h>

#define HAPSIM_DEVICE_ABI_VERSION 1

#ifdef __cplusplus
extern "C" {
#endif

typedef struct hapsim_specs {
    double max_force_n;           /* largest force the device may render */
    double max_stiffness_n_per_m; /* largest stiffness it renders stably */
    double workspace_min_m[3];
    double workspace_max_m[3];
} hapsim_specs;

typedef struct hapsim_state {
    double position_m[3];
    double velocity_m_s[3];
    double gripper;   /* 0 closed .. 1 open */
    uint32_t buttons; /* bit mask */
} hapsim_state;

/* Must return HAPSIM_DEVICE_ABI_VERSION. */
uint32_t hapsim_device_abi_version(void);
/* Opens the device; stores an opaque handle. args may be an empty string. */
int hapsim_device_open(void **handle, const char *args);
int hapsim_device_specs(void *handle, hapsim_specs *out);
int hapsim_device_enable(void *handle);
int hapsim_device_read(void *handle, hapsim_state *out);
int hapsim_device_write_force(void *handle, const double force_n[3]);
/* Zero force, output off. Must not fail. */
void hapsim_device_disable(void *handle);
/* Zero force, release the device. */
void hapsim_device_close(void *handle);

#ifdef __cplusplus
}
#endif

#endif
