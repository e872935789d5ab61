// Times Heitz et al.'s published random walk (MicrosurfaceScattering.cpp/.h, which the bench
// builds from a copy the user names; never part of gonio) for bench/multiple_scattering.py.
//
// usage: driver ggx|beckmann dielectric|conductor ALPHA THETA_DEG sample|eval WALKS
// Gaussian heights, eta 1.51 for a dielectric (F = 1 for a conductor), wi at THETA_DEG from
// the normal in the x-z plane. sample: WALKS calls of sample(wi); eval: WALKS calls of
// eval(wi, wo), wo uniform on the sphere (upper hemisphere for a conductor), drawn before the
// clock starts. Prints one line: walks per CPU-second (CLOCK_PROCESS_CPUTIME_ID, the walks
// alone), then the mean z of the sampled wo and the share below the surface (sample) or the
// mean eval times 4 pi (eval; 2 pi for a conductor), so a wrong build shows.
#include "MicrosurfaceScattering.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <time.h>
#include <vector>

static double cpu_seconds()
{
    timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

int main(int argc, char** argv)
{
    if (argc != 7) {
        std::fprintf(stderr, "usage: %s ggx|beckmann dielectric|conductor ALPHA THETA_DEG "
                             "sample|eval WALKS\n", argv[0]);
        return 2;
    }
    const bool beckmann = std::strcmp(argv[1], "beckmann") == 0;
    const bool conductor = std::strcmp(argv[2], "conductor") == 0;
    const float alpha = float(std::atof(argv[3]));
    const double theta = std::atof(argv[4]) * M_PI / 180.0;
    const bool sampling = std::strcmp(argv[5], "sample") == 0;
    const long walks = std::atol(argv[6]);
    Microsurface* surface = conductor
        ? static_cast<Microsurface*>(new MicrosurfaceConductor(false, beckmann, alpha, alpha))
        : static_cast<Microsurface*>(new MicrosurfaceDielectric(false, beckmann, alpha, alpha,
                                                                1.51f));
    const vec3 wi(float(std::sin(theta)), 0.0f, float(std::cos(theta)));
    double first = 0.0, second = 0.0;
    if (sampling) {
        const double start = cpu_seconds();
        for (long j = 0; j < walks; ++j) {
            const vec3 wo = surface->sample(wi);
            first += wo.z;
            second += wo.z < 0.0f ? 1.0 : 0.0;
        }
        const double seconds = cpu_seconds() - start;
        std::printf("%.6e %.6f %.6f\n", double(walks) / seconds, first / double(walks),
                    second / double(walks));
    } else {
        std::mt19937 directions(12345);
        std::uniform_real_distribution<double> uniform(0.0, 1.0);
        std::vector<vec3> wo(walks);
        for (long j = 0; j < walks; ++j) {
            double z = 2.0 * uniform(directions) - 1.0;
            z = conductor ? std::fabs(z) : z;
            const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
            const double phi = 2.0 * M_PI * uniform(directions);
            wo[j] = vec3(float(r * std::cos(phi)), float(r * std::sin(phi)), float(z));
        }
        const double start = cpu_seconds();
        for (long j = 0; j < walks; ++j)
            first += surface->eval(wi, wo[j]);
        const double seconds = cpu_seconds() - start;
        std::printf("%.6e %.6f %.6f\n", double(walks) / seconds,
                    first / double(walks) * (conductor ? 2.0 : 4.0) * M_PI, 0.0);
    }
    delete surface;
    return 0;
}
