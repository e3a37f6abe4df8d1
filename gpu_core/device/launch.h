/* A work-item's place in its launch (gpu_core/device/kernels.py). Every
 * launch is a 2D grid of rows of at most 32,768 work-items, so that no
 * dimension reaches 65,536 work-items, where PoCL would compile a second
 * work-group function of the kernel. Kernels read their linear indices
 * here, never from the first dimension's work-item functions alone. */
#ifndef GPUGI_LAUNCH_H
#define GPUGI_LAUNCH_H

/* The work-item's linear index in its launch. */
inline int Launch_global_id(void) { return (int)(get_global_id(1) * get_global_size(0) + get_global_id(0)); }

/* The work-group's linear index in its launch. */
inline int Launch_group_id(void) { return (int)(get_group_id(1) * get_num_groups(0) + get_group_id(0)); }

#endif
