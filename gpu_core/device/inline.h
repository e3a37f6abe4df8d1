/* GPUGI_HOT_INLINE marks a small helper that a hot loop calls: PoCL's
 * inliner leaves such helpers as calls (their arguments and results then
 * pass through memory), so its header (pocl_builtins.h) defines the mark
 * as always_inline; every other compiler gets a plain inline and its own
 * judgement. */
#ifndef GPUGI_INLINE_H
#define GPUGI_INLINE_H

#ifndef GPUGI_HOT_INLINE
#define GPUGI_HOT_INLINE inline
#endif

#endif
