// PCA normals of a point set (normals.hpp); moved here from the io module's scan reader, unchanged.
#include "hotgauge/match/normals.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <exception>
#include <flann/flann.hpp>
#include <string>

namespace hotgauge::match {
namespace {

constexpr std::size_t kNormalNeighbours = 12;  // PCA neighbourhood, the point excluded
constexpr std::size_t kBatch = 1 << 16;        // queries per knnSearch: bounded scratch memory
constexpr int kKdLeafSize = 15;                // the k-d tree's leaf size (not measured)

// The normal of a neighbourhood (indices into `points`), towards +z; false for a line or a point.
bool pca_normal(const std::vector<Eigen::Vector3f>& points, const std::size_t* neighbours,
                std::size_t k, Eigen::Vector3f& normal) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (std::size_t j = 0; j < k; ++j) mean += points[neighbours[j]].cast<double>();
    mean /= static_cast<double>(k);
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (std::size_t j = 0; j < k; ++j) {
        const Eigen::Vector3d d = points[neighbours[j]].cast<double>() - mean;
        cov += d * d.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    const Eigen::Vector3d ev = eig.eigenvalues();  // ascending
    if (!(ev[1] > 1e-12 * ev[2])) return false;    // a line or a point: no plane
    Eigen::Vector3d n = eig.eigenvectors().col(0);
    if (n.z() < 0) n = -n;
    normal = n.cast<float>();
    return true;
}

}  // namespace

core::Result<OrientedPoints> estimate_normals(const std::vector<Eigen::Vector3f>& points) {
    const std::size_t n = points.size();
    OrientedPoints out;
    if (n == 0) return out;  // FLANN's index wants at least one point
    std::vector<float> flat;
    flat.reserve(3 * n);
    for (const Eigen::Vector3f& p : points) flat.insert(flat.end(), {p.x(), p.y(), p.z()});
    const std::size_t k = std::min(n, kNormalNeighbours + 1);  // the point itself comes first
    std::vector<std::size_t> idx(std::min(n, kBatch) * k);
    std::vector<float> dist(idx.size());
    try {
        flann::Matrix<float> data(flat.data(), n, 3);
        flann::Index<flann::L2_Simple<float>> index(data,
                                                    flann::KDTreeSingleIndexParams(kKdLeafSize));
        index.buildIndex();
        flann::SearchParams params(flann::FLANN_CHECKS_UNLIMITED);
        for (std::size_t first = 0; first < n; first += kBatch) {
            const std::size_t m = std::min(kBatch, n - first);
            flann::Matrix<float> queries(flat.data() + 3 * first, m, 3);
            flann::Matrix<std::size_t> indices(idx.data(), m, k);
            flann::Matrix<float> dists(dist.data(), m, k);
            index.knnSearch(queries, indices, dists, k, params);
            for (std::size_t q = 0; q < m; ++q) {
                Eigen::Vector3f normal;
                if (!pca_normal(points, idx.data() + q * k, k, normal)) continue;
                out.points.push_back(points[first + q]);
                out.normals.push_back(normal);
            }
        }
    } catch (const std::exception& e) {
        return core::make_error(std::string("normal estimation failed: ") + e.what());
    }
    return out;
}

}  // namespace hotgauge::match
