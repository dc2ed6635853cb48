/* The one header bindgen reads. build.rs defines DOFRAY_EMBREE4 when it found Embree 4. */
#ifdef DOFRAY_EMBREE4
#include <embree4/rtcore.h>
#else
#include <embree3/rtcore.h>
#endif
