// gonio's conformance probe: read one ASTM E1392 or Zemax tabular BSDF file with libbsdf's own
// readers and print the BSDF value libbsdf returns at each pair of directions given on stdin.
//
// Usage: libbsdf_probe astm-brdf|astm-btdf|zemax FILE < directions
// Each input line: wi_x wi_y wi_z wo_x wo_y wo_z (libbsdf's frame; wo_z < 0 on a BTDF's side).
// Output: a line `type BRDF|BTDF` (the reader's data type), then one line `value V` (1/sr, the
// first spectral channel) per input line, among libbsdf's own log lines. Exit status 1 with a message when a reader refuses.
#include <iostream>
#include <memory>
#include <string>

#include <libbsdf/Brdf/Brdf.h>
#include <libbsdf/Brdf/Btdf.h>
#include <libbsdf/Common/Global.h>
#include <libbsdf/Reader/AstmReader.h>
#include <libbsdf/Reader/ZemaxBsdfReader.h>

int main(int argc, char** argv)
{
    if (argc != 3) {
        std::cerr << "usage: libbsdf_probe astm-brdf|astm-btdf|zemax FILE < directions\n";
        return 2;
    }
    const std::string kind = argv[1];
    const std::string path = argv[2];
    std::shared_ptr<lb::Brdf> brdf;
    lb::DataType type = lb::BRDF_DATA;
    if (kind == "astm-brdf" || kind == "astm-btdf") {
        brdf.reset(lb::AstmReader::read(path));
        type = kind == "astm-btdf" ? lb::BTDF_DATA : lb::BRDF_DATA;
    }
    else if (kind == "zemax") {
        brdf.reset(lb::ZemaxBsdfReader::read(path, &type));
    }
    else {
        std::cerr << "libbsdf_probe: unknown kind " << kind << "\n";
        return 2;
    }
    if (!brdf) {
        std::cerr << "libbsdf_probe: libbsdf could not read " << path << "\n";
        return 1;
    }
    const lb::Btdf btdf(brdf);
    std::cout.precision(9);
    std::cout << "type " << (type == lb::BTDF_DATA ? "BTDF" : "BRDF") << "\n";
    double v[6];
    while (std::cin >> v[0] >> v[1] >> v[2] >> v[3] >> v[4] >> v[5]) {
        const lb::Vec3 wi(v[0], v[1], v[2]);
        const lb::Vec3 wo(v[3], v[4], v[5]);
        const lb::Spectrum value = type == lb::BTDF_DATA ? btdf.getSpectrum(wi, wo)
                                                         : brdf->getSpectrum(wi, wo);
        std::cout << "value " << static_cast<double>(value[0]) << "\n";
    }
    std::cout << std::flush;
    return 0;
}
