/* Every header of the path tracer, in the order they build on each other: what an entry point
 * (render.cl, wavefront.cl, wavefront_lanes.cl) includes. */
#ifndef VOLCL_RENDERER_H
#define VOLCL_RENDERER_H

#include "types.h"
#include "common.h"
#include "rng.h"
#include "sampling.h"
#include "scene.h"
#include "bvh.h"
#include "surface.h"
#include "bsdf.h"
#include "phase.h"
#include "grid.h"
#include "media.h"
#include "lights.h"
#include "equiangular.h"
#include "camera.h"
#include "integrator.h"
#include "direct.h"
#include "sample.h"

#endif
