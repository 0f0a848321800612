/* CMake probe (tests/wire/CMakeLists.txt): -m32 compiles, links libm, and runs here. */
#include <math.h>
int main(void) {
    return sizeof(void*) == 4 && (int)sqrtf(1.0f) == 1 ? 0 : 1;
}
